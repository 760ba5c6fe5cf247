"""The refusal cases of issue 12 (tests/integrity_cases.py) through the console script, as a markdown table:
command, exit status, the message (stderr), what is left on disk besides what the case set up.

Usage: python benchmarks/integrity_table.py
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from integrity_cases import CASES, left_behind, prepare  # noqa: E402

from ddmr_cli.storage import jobdir  # noqa: E402


def main() -> int:
    ddmr = str(Path(sys.executable).with_name("ddmr"))
    print("| # | command | exit | message (stderr) | left on disk |")
    print("|---|---|---|---|---|")
    wrong = 0
    for i, case in enumerate(CASES, 1):
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            args = prepare(case, work)
            with contextlib.ExitStack() as stack:
                if case.setup == "lock":
                    stack.enter_context(jobdir.DirLock(work / "locked"))
                proc = subprocess.run([ddmr, "run", *args], cwd=work, capture_output=True, text=True)
            left = left_behind(work, case)
            shown = " ".join(a.replace(tmp, "$TMP") for a in args)
            shown = shown if len(shown) < 90 else shown[:60] + "..." + shown[-20:]
            err = proc.stderr.strip().replace(tmp, "$TMP").replace("|", "\\|")
            err = err if len(err) < 240 else err[:130] + "..." + err[-100:]
            ok = proc.returncode == case.exit and case.message in proc.stderr.replace(tmp, str(work)) and not left
            wrong += not ok
            print(f"| {i} | `ddmr run {shown}` | {proc.returncode} | `{err}` | {', '.join(left) or 'nothing'}"
                  f"{'' if ok else ' **UNEXPECTED**'} |")
    print(f"\n{len(CASES) - wrong} of {len(CASES)} as expected")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
