"""The designs of the sensitivity study (docs/model.md §11): which samples a stage simulates.

Every design is a pure function of the ``study`` config (box, sizes, ``sampler_seed``) and the faithful reading,
so every job of a sweep computes the same list and takes its own share (:func:`chunk_of`); nothing is handed
between processes or machines. SALib draws the Morris trajectories, the Sobol (Saltelli) matrices and the Latin
hypercube on the unit cube; :meth:`~ddmr_cli.study.space.Parameter.from_unit` maps them onto the box.

Stages: ``oat`` (each parameter over its grid, the others faithful), ``morris`` (screening of every global
parameter), ``sobol`` (the parameters ``study.sobol.parameters``, the others faithful), ``map`` (a grid over
two parameters), ``lhs`` (Latin hypercube over the global box: uniform, for the share of the box where each
claim holds), ``calibration`` (one trial of the Optuna search, :mod:`ddmr_cli.study.search`: the reading
``study.reading`` the sweeper sampled), ``points`` (named readings).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ddmr_cli.errors import ConfigError
from ddmr_cli.study.space import Box
from ddmr_cli.study.stages import STAGES


@dataclass
class Design:
    """A stage's samples.

    Attributes
    ----------
    stage : str
    names : list of str
        The parameters the design varies (the others stay faithful).
    samples : list of dict
        Every sample's complete reading: parameter -> value (the faithful values filled in).
    labels : list of str
        Per sample: what it is (``oat``: the parameter varied, ``faithful``; ``points``: the reading's name).
    unit : ndarray (n_samples, len(names))
        The samples on the unit cube, as SALib's analyses take them (NaN where a sample is not on it).
    """

    stage: str
    names: list[str]
    samples: list[dict[str, Any]]
    labels: list[str] = field(default_factory=list)
    unit: np.ndarray | None = None


def problem(names: list[str]) -> dict:
    """SALib's problem on the unit cube of ``names``."""
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


def _from_unit(box: Box, names: list[str], unit: np.ndarray, faithful: Mapping[str, Any], stage: str) -> Design:
    samples = [{**faithful, **{n: box[n].from_unit(u) for n, u in zip(names, row)}} for row in unit]
    return Design(stage, names, samples, [stage] * len(samples), unit)


def oat(box: Box, faithful: Mapping[str, Any], levels: int,
        readings: Mapping[str, Mapping[str, Any]] | None = None, full: Box | None = None) -> Design:
    """The named readings (the faithful one first; parameters of ``full``, default ``box``), then every parameter
    of ``box`` over its grid, the others faithful."""
    named = points(full or box, faithful, {"faithful": {}, **(readings or {})})
    samples, labels = named.samples, named.labels
    for p in box.parameters:
        for value in p.grid(levels):
            samples.append({**faithful, p.name: value})
            labels.append(p.name)
    return Design("oat", box.names, samples, labels, None)


def morris(box: Box, faithful: Mapping[str, Any], trajectories: int, levels: int, seed: int) -> Design:
    from SALib.sample import morris as morris_sample

    names = box.global_names()
    unit = morris_sample.sample(problem(names), N=trajectories, num_levels=levels, seed=seed)
    return _from_unit(box, names, unit, faithful, "morris")


def sobol(box: Box, faithful: Mapping[str, Any], names: list[str], base: int, seed: int) -> Design:
    from SALib.sample import sobol as sobol_sample

    for n in names:
        if box[n].oat_only:
            raise ConfigError("study.sobol.parameters", n, "is an OAT-only parameter")
    unit = sobol_sample.sample(problem(list(names)), N=base, calc_second_order=False, scramble=True, seed=seed)
    return _from_unit(box, list(names), unit, faithful, "sobol")


def grid_map(box: Box, faithful: Mapping[str, Any], x: str, y: str, levels: int) -> Design:
    """A ``levels x levels`` grid over parameters x and y (on their own axes)."""
    xs, ys = box[x].grid(levels), box[y].grid(levels)
    samples = [{**faithful, x: vx, y: vy} for vy in ys for vx in xs]
    unit = np.array([[box[x].to_unit(s[x]), box[y].to_unit(s[y])] for s in samples])
    return Design("map", [x, y], samples, ["map"] * len(samples), unit)


def latin(box: Box, faithful: Mapping[str, Any], samples: int, seed: int) -> Design:
    from SALib.sample import latin as latin_sample

    names = box.global_names()
    unit = latin_sample.sample(problem(names), N=samples, seed=seed)
    return _from_unit(box, names, unit, faithful, "lhs")


def points(box: Box, faithful: Mapping[str, Any], readings: Mapping[str, Mapping[str, Any]]) -> Design:
    samples, labels = [], []
    for name, values in readings.items():
        for key in values:
            box[key]  # noqa: B018 (raises on an unknown parameter)
        samples.append({**faithful, **dict(values)})
        labels.append(str(name))
    return Design("points", box.names, samples, labels, None)


def build(study, box: Box, faithful: Mapping[str, Any], sweep_dir=None) -> Design:
    """The design of ``study.stage`` (a composed ``study`` node); ``sweep_dir`` is the stage's sweep dir (where
    ``study.calibrated`` looks for ``../calibration/calibration.json``)."""
    from omegaconf import OmegaConf

    stage = str(study.stage)
    seed = int(study.sampler_seed)
    full = box
    vary = study.get("vary")
    box = box.restricted(None if vary is None else [str(n) for n in vary])
    if stage == "oat":
        return oat(box, faithful, int(study.oat.levels), OmegaConf.to_container(study.points, resolve=True),
                   full=full)
    if stage == "morris":
        return morris(box, faithful, int(study.morris.trajectories), int(study.morris.levels), seed)
    if stage == "sobol":
        return sobol(box, faithful, [str(n) for n in study.sobol.parameters], int(study.sobol.base), seed)
    if stage == "map":
        return grid_map(box, faithful, str(study.map.x), str(study.map.y), int(study.map.levels))
    if stage == "lhs":
        return latin(box, faithful, int(study.lhs.samples), seed)
    if stage == "calibration":  # one trial of the search: the sampled reading, the rest faithful
        from ddmr_cli.study.space import reading_of

        return Design("calibration", box.global_names(), [{**faithful, **reading_of(study, full)}], ["trial"], None)
    if stage == "points":
        readings = OmegaConf.to_container(study.points, resolve=True)
        if study.get("calibrated"):
            from pathlib import Path

            if sweep_dir is None:
                raise ConfigError("study.calibrated", True, "needs the stage's sweep dir")
            readings["calibrated"] = calibrated_reading(Path(sweep_dir).parent / "calibration" / "calibration.json")
        return points(full, faithful, readings)
    raise ConfigError("study.stage", stage, f"must be one of {', '.join(STAGES)}")


def calibrated_reading(path) -> dict[str, Any]:
    """The best reading of a calibration stage's ``calibration.json``."""
    import json
    from pathlib import Path

    try:
        result = json.loads(Path(path).read_text(encoding="utf-8"))
        return dict(result["reading"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError("study.calibrated", True, f"no calibration result at {path} ({exc})") from None


def chunk_of(n_samples: int, chunk: int, chunks: int) -> list[int]:
    """The sample indices of job ``chunk`` of ``chunks``: chunk, chunk + chunks, ... (interleaved, so every job
    gets a share of each part of a design)."""
    if chunks < 1:
        raise ConfigError("study.chunks", chunks, "must be >= 1")
    if not 0 <= chunk < chunks:
        raise ConfigError("study.chunk", chunk, f"must be in 0 .. study.chunks - 1 = {chunks - 1}")
    return list(range(chunk, n_samples, chunks))


__all__ = ["Design", "STAGES", "problem", "build", "chunk_of", "oat", "morris", "sobol", "grid_map", "latin", "points"]
