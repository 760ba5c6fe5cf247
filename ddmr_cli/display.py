"""How the report shows a controller: its label, line style and rank (order in tables and figures), read from the
``display`` node of its config (issue 27), the one place they are written.

Every ``conf/controller/*.yaml`` sets ``display`` (label, colour, dash, marker, width, rank). The report reads it
from a job's saved config, or from the packaged YAML when it knows only the controller's name (a job dir written
before the node existed, the tuning and realism sections). A controller without the node (a user's YAML) still
works: its label is its name, its style a free combination (:class:`~ddmr_cli.plots.common.StyleBook`), its
rank after the packaged ones (then by name). A YAML that extends another (``defaults: [smc_ndo, _self_]``)
inherits that one's ``display`` through Hydra: for a controller that is not packaged, the values it shares with the
packaged controller it agrees with most (:data:`WEIGHTS`: the one it extends) are that inheritance, not the user's
choice, and are read as absent (two controllers of a report never share a label or a style that way).

No heavy imports: the config validation (:func:`check`) reads this module too.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from importlib import resources
from typing import Any, Mapping

from ddmr_cli.errors import ConfigError

#: The controller config node this module reads (never passed to a controller's constructor).
DISPLAY = "display"
#: Dash patterns (matplotlib on/off sequences), told apart even on a noisy line.
DASHES = {
    "solid": "-", "dashed": (0, (5, 2)), "dotted": (0, (1, 1.4)), "dashdot": (0, (6, 2, 1.2, 2)),
    "long": (0, (11, 3)), "dashdotdot": (0, (6, 2, 1.2, 2, 1.2, 2)), "sparse": (0, (2, 4)),
}
MARKERS = (None, "o", "s", "^", "D", "v", "x", "P")
#: Line width of a controller whose config does not set one.
WIDTH = 1.1
#: How much a shared value says that a controller's YAML extends a packaged one: the label and the rank are each a
#: packaged controller's alone, the colour nearly so (at most three share one), then the dash.
WEIGHTS = {"label": 16, "rank": 16, "colour": 4, "dash": 2, "width": 1, "marker": 1}
_COLOUR = re.compile(r"#[0-9a-fA-F]{6}")
#: The keys of a display node and the rule each value follows.
RULES = {
    "label": "must be a non-empty text",
    "colour": 'must be a colour "#rrggbb"',
    "dash": f"must be one of {', '.join(DASHES)}",
    "marker": f"must be null or one of {', '.join(m for m in MARKERS if m)}",
    "width": "must be a number > 0",
    "rank": "must be an integer >= 0 (order in tables and figures, smallest first)",
}


@dataclass(frozen=True)
class Display:
    """A controller's label, style (None where the report picks a free one) and rank (inf: after the ranked)."""

    name: str
    label: str
    colour: str | None = None
    dash: str | None = None
    marker: str | None = None
    width: float | None = None
    rank: float = math.inf

    @property
    def order(self) -> tuple[float, str]:
        """Sort key: rank, then name."""
        return (self.rank, self.name)


def _ok(key: str, value: Any) -> bool:
    if key == "label":
        return isinstance(value, str) and bool(value.strip())
    if key == "colour":
        return isinstance(value, str) and bool(_COLOUR.fullmatch(value))
    if key == "dash":
        return value in DASHES
    if key == "marker":
        return value in MARKERS
    if key == "width":
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def check(node: Mapping | None, path: str = f"controller.{DISPLAY}") -> None:
    """Raise :class:`~ddmr_cli.errors.ConfigError` naming the key on a bad value of a display node (an unset
    value, null, is always fine)."""
    for key, value in (node or {}).items():
        if key not in RULES:
            raise ConfigError(f"{path}.{key}", value, f"unknown key; known: {', '.join(RULES)}")
        if value is not None and not _ok(key, value):
            raise ConfigError(f"{path}.{key}", value, RULES[key])


def packaged(name: str) -> dict:
    """The display node ``conf/controller/<name>.yaml`` itself sets ({} when there is no such file or node)."""
    import yaml

    path = resources.files("ddmr_cli.conf").joinpath("controller", f"{name}.yaml")
    if not path.is_file():
        return {}
    return dict((yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get(DISPLAY) or {})


def packaged_all() -> dict[str, dict]:
    """Every packaged controller's own display node, by name."""
    folder = resources.files("ddmr_cli.conf").joinpath("controller")
    names = sorted(p.name[:-len(".yaml")] for p in folder.iterdir() if p.name.endswith(".yaml"))
    return {n: packaged(n) for n in names}


def _display(name: str, values: Mapping) -> Display:
    values = {k: v for k, v in values.items() if k in RULES and v is not None}
    return Display(name, str(values.get("label", name)), values.get("colour"), values.get("dash"),
                   values.get("marker"), None if values.get("width") is None else float(values["width"]),
                   float(values["rank"]) if "rank" in values else math.inf)


def of(name: str, config: Mapping | None = None) -> Display:
    """The display of controller ``name``: from ``config`` (the ``display`` node of its job's config) when given,
    else from the packaged YAML. For a controller that is not packaged, the values it shares with the packaged
    controller it agrees with most are inherited (its YAML extends that one) and read as absent."""
    if config is None:
        return _display(name, packaged(name))
    own = {k: v for k, v in dict(config).items() if v is not None}
    if not packaged(name):  # the packaged YAML it agrees with most is the one it extends
        def agreement(node: Mapping) -> int:
            return sum(WEIGHTS.get(k, 0) for k, v in node.items() if v is not None and own.get(k) == v)

        parent = max(packaged_all().values(), key=agreement, default={})
        own = {k: v for k, v in own.items() if parent.get(k) != v}
    return _display(name, own)


def of_job(name: str, config: Mapping | None) -> Display:
    """The display of a job's controller from its saved config (a dict), or from the packaged YAML when the config
    has no display node (a job dir written before it existed)."""
    node = ((config or {}).get("controller") or {}).get(DISPLAY) if isinstance(config, Mapping) else None
    return of(name, node)


def label(name: str) -> str:
    """The packaged label of a controller (its name when it has none)."""
    return of(name).label


def rank(name: str) -> tuple[float, str]:
    """Sort key of a controller known by name only: its packaged rank (inf when it has none), then its name."""
    return of(name).order


__all__ = ["Display", "DISPLAY", "DASHES", "MARKERS", "WIDTH", "RULES", "WEIGHTS", "check", "packaged", "packaged_all", "of",
           "of_job", "label", "rank"]
