"""``ddmr report``: the paper's tables and figures from a sweep (being built)."""


def build_report(path, out=None):
    from ..errors import DDMRError

    raise DDMRError("ddmr report is not implemented yet")
