"""Metrics of one run, computed as the run goes (docs/model.md §7).

The step loop calls :func:`accumulate` at every step of every run; it adds the step, in time order, to running
sums per run for the whole run, each terrain zone and each scenario phase, and to a second, steady-state set of
the same sums that counts only the steps after settling: from ``settle_time`` on (the start-up transient) for the whole run, and for a zone
(phase) from ``settle_time`` on and ``zone_settle_time`` after the run entered it. A step is added once, to the run's
block (the sums since its segments last changed, :func:`flush`), and a block is added to each of its segments
when they change and at the end: 26 additions a step instead of up to 156. Memory does not grow with the
duration, and the rounding is the same whatever the batch size and chunk size (blocks follow the run, not the
chunks). The metrics are built from the
sums in :meth:`MetricAccumulator.finalize`; the steady-state ones carry the suffix :data:`STEADY` (``_ss``).

Chattering: total variation of the applied voltage per second (V/s), and the fraction of the variance of
``u`` that passes a 2nd-order Butterworth high-pass at ``hf_cutoff`` Hz (the "power above 10 Hz" of
docs/model.md §7, computed online with the filter started at steady state for the first voltage).
"""

from __future__ import annotations

import math

import numpy as np

from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.engine.catalog import HF_CUTOFF, METRICS, STEADY

#: Per-step sums kept per run and segment (column order of :func:`accumulate`); ``_R``/``_L`` per wheel.
SUMS = ("count", "dev", "dev2", "tdev", "abs_ex", "abs_ey", "abs_eth", "saturated",
        "abs_du_R", "abs_du_L", "u2_R", "u2_L", "power_R", "power_L", "abs_dtilde_R", "abs_dtilde_L",
        "abs_dtilde_ndo_R", "abs_dtilde_ndo_L", "abs_s_R", "abs_s_L", "u_R", "u_L", "u_hp2_R", "u_hp2_L",
        "abs_u_R", "abs_u_L")
N_SUMS = len(SUMS)

#: The estimation metrics: name -> the names of the controller's ESTIMATE channels whose summed estimate of d it
#: compares with the true d (None: all of them). ``d_est_mae_ndo`` keeps the paper's "NDO part alone" by name (0
#: for a controller without an NDO: then it is the mean |d|). The engine sums ``|d - sum of the member channels|``
#: per metric (the membership rows of :func:`estimation_membership`), in the order :data:`SUMS` names them.
ESTIMATION_METRICS: dict[str, tuple[str, ...] | None] = {"d_est_mae": None, "d_est_mae_ndo": ("NDO",)}


def estimation_membership(channels) -> np.ndarray:
    """``(len(ESTIMATION_METRICS), max(1, n))`` int64: row ``i`` lists, in channel order, the channels ``c`` (a
    :class:`~ddmr_cli.control.base.Diagnostic` each) whose estimate counts in metric ``i``, then -1 (the step loop
    subtracts the listed channels and stops at the first -1)."""
    from ddmr_cli.control.base import ESTIMATE

    out = np.full((len(ESTIMATION_METRICS), max(1, len(channels))), -1, dtype=np.int64)
    for i, names in enumerate(ESTIMATION_METRICS.values()):
        members = [c for c, channel in enumerate(channels)
                   if channel.kind == ESTIMATE and (names is None or channel.name in names)]
        out[i, :len(members)] = members
    return out


def butterworth_highpass(cutoff: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """2nd-order Butterworth high-pass by the bilinear transform with pre-warping, as one biquad
    ``[b0, b1, b2, 1, a1, a2]`` (what ``scipy.signal.butter(2, cutoff, 'highpass', fs=1/dt, output='sos')``
    gives), and the direct-form-II-transposed state per unit input at steady state (DC gain 0: ``[-b0, b2]``).
    A cutoff at or above Nyquist passes nothing."""
    if cutoff >= 0.5 / dt:
        return np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]), np.zeros(2)
    k = math.tan(math.pi * cutoff * dt)
    norm = 1.0 / (1.0 + math.sqrt(2.0) * k + k * k)
    b0 = norm
    sos = np.array([b0, -2.0 * b0, b0, 1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - math.sqrt(2.0) * k + k * k) * norm])
    return sos, np.array([-b0, b0])


#: runs whose metrics :meth:`MetricAccumulator.finalize` computes at once: its temporaries stay about a MiB at any
#: number of seeds (10,000 seeds at once: 10 MiB beside the sums)
FINALIZE_BLOCK_RUNS = 1024

#: Per-run fields of the accumulator's state (a structured record, beside the engine's run state): the last
#: voltage and high-pass state, the largest deviation (all steps and steady steps), the last one, and the step at
#: which the run entered its current zone and phase segment.
ACCUMULATOR_FIELDS = [("u_prev", "f8", 2), ("hp_state", "f8", (2, 2)), ("started", "?"), ("dev_max", "f8"),
                      ("dev_max_ss", "f8"), ("dev_final", "f8"), ("zone_segment", "i8"), ("zone_entry", "i8"),
                      ("phase_segment", "i8"), ("phase_entry", "i8"), ("block", "f8", N_SUMS), ("block_key", "i8")]


@law
def block_key(zone_segment, phase_segment, steady, steady_zone, steady_phase):
    """The segments a step counts in, as one number: zone and phase segment and the three steady flags."""
    return (((zone_segment * 4096 + phase_segment) * 2 + steady) * 2 + steady_zone) * 2 + steady_phase


@law
def add_block(sums, r, key, block):
    """Add a block of sums (``block``, one per column of :data:`SUMS`, the steps since run ``r``'s segments last
    changed, their :func:`block_key` ``key``) to every segment it counts in (whole run, zone, phase, and their steady
    twins at segment index + the number of segments), and empty it."""
    n = sums.shape[1] // 2
    steady_phase, key = key % 2, key // 2
    steady_zone, key = key % 2, key // 2
    steady, key = key % 2, key // 2
    p, z = key % 4096, key // 4096
    for c in range(block.shape[0]):
        v = block[c]
        sums[r, 0, c] += v
        sums[r, z, c] += v
        sums[r, p, c] += v
        if steady:
            sums[r, n, c] += v
        if steady_zone:
            sums[r, n + z, c] += v
        if steady_phase:
            sums[r, n + p, c] += v
        block[c] = 0.0


@law
def flush(sums, r, acc):
    """Add the run's block (the sums of its steps since the segments last changed) to its segments
    (:func:`add_block`), and empty it."""
    key = acc["block_key"]
    if key < 0:
        return
    add_block(sums, r, key, acc["block"])
    acc["block_key"] = -1


@law
def segment_key(k, zone_segment, phase_segment, zone_now, zone_entry, phase_now, phase_entry, settle_steps,
                zone_settle_steps):
    """Step ``k``'s block key (:func:`block_key`) in zone segment ``zone_segment`` and phase segment
    ``phase_segment``, given the segments the run was in (``zone_now``, ``phase_now``) and the steps it entered
    them: ``(key, zone_entry, phase_entry)`` after the step. A step is steady for the whole run from step
    ``settle_steps`` on, and for its zone (phase) once the run has also been ``zone_settle_steps`` in it."""
    zone_entry = k if zone_segment != zone_now else zone_entry
    phase_entry = k if phase_segment != phase_now else phase_entry
    ss = k >= settle_steps
    sz = ss and k - zone_entry >= zone_settle_steps
    sp = ss and k - phase_entry >= zone_settle_steps
    return block_key(zone_segment, phase_segment, ss, sz, sp), zone_entry, phase_entry


@law
def step_terms(t, dev, e_x, e_y, e_theta, saturated, u_R, u_L, u_prev_R, u_prev_L, w_R, w_L, dtilde_R, dtilde_L,
               dtilde_ndo_R, dtilde_ndo_L, s_R, s_L, hp_out_R, hp_out_L, k_e, r_a):
    """One step's term of every sum of :data:`SUMS`, in its order (docs/model.md §7): the step's count, deviation,
    its square and its time-weighted value, the absolute pose errors, the saturation flag, the voltage's change,
    square, electrical power ``u (u - k_e w) / R_a``, the absolute estimation errors ``d - d_hat`` (all estimates,
    the NDO's), ``|s|``, ``u``, the high-passed voltage's square and ``|u|``."""
    return (1.0, dev, dev * dev, t * dev, abs(e_x), abs(e_y), abs(e_theta), 1.0 if saturated else 0.0,
            abs(u_R - u_prev_R), abs(u_L - u_prev_L), u_R * u_R, u_L * u_L,
            u_R * (u_R - k_e * w_R) / r_a, u_L * (u_L - k_e * w_L) / r_a,
            abs(dtilde_R), abs(dtilde_L), abs(dtilde_ndo_R), abs(dtilde_ndo_L), abs(s_R), abs(s_L), u_R, u_L,
            hp_out_R * hp_out_R, hp_out_L * hp_out_L, abs(u_R), abs(u_L))


@law
def highpass(hp, state0, state1, u):
    """One step of the biquad ``hp`` (direct form II transposed, as ``scipy.signal.sosfilt``) on input ``u``:
    ``(y, state0, state1)`` after it."""
    y = hp[0] * u + state0
    return y, hp[1] * u - hp[4] * y + state1, hp[2] * u - hp[5] * y


@law
def estimation_error(d, diagnostics, members, wheel):
    """``d`` less the estimates of the channels ``members`` lists (then -1) of ``diagnostics`` (one wheel)."""
    dtilde = d
    for m in range(members.shape[0]):
        c = members[m]
        if c < 0:
            break
        dtilde -= diagnostics[c, wheel]
    return dtilde


@law
def add_terms(block, terms):
    """A step's terms (:func:`step_terms`) added to a run's block of sums, written out (a loop over a tuple's entries
    indexes it at run time: 1.5x the step loop's time)."""
    block[0] += terms[0]
    block[1] += terms[1]
    block[2] += terms[2]
    block[3] += terms[3]
    block[4] += terms[4]
    block[5] += terms[5]
    block[6] += terms[6]
    block[7] += terms[7]
    block[8] += terms[8]
    block[9] += terms[9]
    block[10] += terms[10]
    block[11] += terms[11]
    block[12] += terms[12]
    block[13] += terms[13]
    block[14] += terms[14]
    block[15] += terms[15]
    block[16] += terms[16]
    block[17] += terms[17]
    block[18] += terms[18]
    block[19] += terms[19]
    block[20] += terms[20]
    block[21] += terms[21]
    block[22] += terms[22]
    block[23] += terms[23]
    block[24] += terms[24]
    block[25] += terms[25]


@inlined_law
def accumulate(sums, r, acc, k, settle_steps, zone_settle_steps, zone_segment, phase_segment, t, dev, e_x, e_y, e_theta, saturated,
               u_R, u_L, w_R, w_L, s_R, s_L, d_R, d_L, diagnostics, estimation, k_e, r_a, hp, hp_zi):
    """Add step ``k`` of run ``r`` to ``sums[r, segment, column]`` (columns: :data:`SUMS`; docs/model.md §7).

    The step's segments and steadiness are :func:`segment_key`'s, its terms :func:`step_terms`. ``hp`` is one
    biquad ``[b0, b1, b2, a0, a1, a2]`` (:func:`highpass`), its state ``acc["hp_state"]`` started at ``hp_zi * u``
    on the first step (no transient); ``acc["u_prev"]`` is the last voltage, for the total variation.
    ``diagnostics[c, wheel]`` are the controller's channels, ``estimation[i]`` the channels whose estimates count in
    estimation metric ``i`` (then -1; :func:`estimation_membership`; :data:`ESTIMATION_METRICS`: all estimates,
    the NDO alone).
    """
    if not acc["started"]:
        acc["u_prev"][0], acc["u_prev"][1] = u_R, u_L
        acc["hp_state"][0, 0], acc["hp_state"][0, 1] = hp_zi[0] * u_R, hp_zi[1] * u_R
        acc["hp_state"][1, 0], acc["hp_state"][1, 1] = hp_zi[0] * u_L, hp_zi[1] * u_L
        acc["started"] = True
    key, acc["zone_entry"], acc["phase_entry"] = segment_key(
        k, zone_segment, phase_segment, acc["zone_segment"], acc["zone_entry"], acc["phase_segment"],
        acc["phase_entry"], settle_steps, zone_settle_steps)
    acc["zone_segment"], acc["phase_segment"] = zone_segment, phase_segment
    if key != acc["block_key"]:
        flush(sums, r, acc)
        acc["block_key"] = key
    hs = acc["hp_state"]
    y_R, hs[0, 0], hs[0, 1] = highpass(hp, hs[0, 0], hs[0, 1], u_R)
    y_L, hs[1, 0], hs[1, 1] = highpass(hp, hs[1, 0], hs[1, 1], u_L)
    terms = step_terms(t, dev, e_x, e_y, e_theta, saturated, u_R, u_L, acc["u_prev"][0], acc["u_prev"][1], w_R, w_L,
                       estimation_error(d_R, diagnostics, estimation[0], 0),
                       estimation_error(d_L, diagnostics, estimation[0], 1),
                       estimation_error(d_R, diagnostics, estimation[1], 0),
                       estimation_error(d_L, diagnostics, estimation[1], 1), s_R, s_L, y_R, y_L, k_e, r_a)
    acc["u_prev"][0], acc["u_prev"][1] = u_R, u_L
    add_terms(acc["block"], terms)
    if dev > acc["dev_max"]:
        acc["dev_max"] = dev
    if k >= settle_steps and dev > acc["dev_max_ss"]:
        acc["dev_max_ss"] = dev
    acc["dev_final"] = dev


def _wheel_sum(pair: np.ndarray) -> np.ndarray:
    """Right wheel plus left (the first axis, of 2): numpy's ``sum`` over the pair to the bit, without its reduction
    over a two-element axis (60-75 us an array of 1,000 runs)."""
    return pair[0] + pair[1]


def _wheel_mean(pair: np.ndarray) -> np.ndarray:
    """The mean of the two wheels (the first axis, of 2): numpy's ``mean`` over the pair to the bit (its sum, over
    2)."""
    return _wheel_sum(pair) / 2.0


class MetricAccumulator:
    """Running sums per run for the whole run (segment 0), each zone and each phase, filled by
    :func:`accumulate` inside the step loop; :meth:`finalize` turns them into the metrics.

    Parameters
    ----------
    n_runs : int
    dt : float
        Step [s].
    zone_names, phase_names : list of str
    hf_cutoff : float
        High-pass cutoff for the chattering spectrum fraction [Hz].

    ``sums[r, j]`` holds segment ``j`` of :attr:`segments` over every step, ``sums[r, n_segments + j]`` over its
    steady steps, until :meth:`finalize` writes the metrics over them.
    """

    def __init__(self, n_runs: int, dt: float, zone_names, phase_names, hf_cutoff: float = HF_CUTOFF) -> None:
        self.n_runs, self.dt = n_runs, dt
        self.zone_names, self.phase_names = list(zone_names), list(phase_names)
        self.segments = ["total"] + [f"zone:{z}" for z in self.zone_names] + [f"phase:{p}" for p in self.phase_names]
        self.phase_base = 1 + len(self.zone_names)
        self.sums = np.zeros((n_runs, 2 * len(self.segments), N_SUMS))
        self.hf_cutoff = hf_cutoff
        self.hp, self.hp_zi = butterworth_highpass(hf_cutoff, dt)

    @staticmethod
    def initial_state(state: np.ndarray) -> None:
        """Set the accumulator fields of a run-state array (:data:`ACCUMULATOR_FIELDS`) before the first step."""
        state["dev_max"] = state["dev_max_ss"] = -np.inf
        state["dev_final"] = np.nan
        state["started"] = False
        state["zone_segment"] = state["phase_segment"] = -1
        state["block_key"] = -1

    def finalize(self, state: np.ndarray) -> dict[str, np.ndarray]:
        """Metrics per run and segment from the sums and the run-state array: ``{name: array (n_runs, n_segments)}``
        for every metric of :data:`METRICS` and its steady-state twin ``name + STEADY`` (NaN where a segment is
        empty). The step loop has added each run's last block to its segments at the run's last step
        (:func:`flush`), so this is numpy on the sums alone.

        The metrics are written over the sums they come from (:attr:`sums` holds them afterwards: call once), a
        block of runs at a time, each block's metrics computed in full from its own rows before they are
        written there: a run's metrics take fewer numbers than its sums (``2 len(METRICS)`` against
        ``2 N_SUMS`` a segment), and the largest batch's memory peaks here (10,000 seeds: the 17 MiB of
        metrics came on top of the 20 MiB of sums). Each metric is a view ``(n_runs, n_segments)`` of that
        memory; the numbers are those of separate arrays, to the bit."""
        n, names = len(self.segments), [*METRICS, *(name + STEADY for name in METRICS)]
        rows = self.sums.reshape(self.n_runs, -1)
        if len(names) * n > rows.shape[1]:  # pragma: no cover - METRICS outgrew SUMS: separate arrays
            rows = np.empty((self.n_runs, len(names) * n))
        out = {name: rows[:, i * n:(i + 1) * n] for i, name in enumerate(names)}
        for first in range(0, self.n_runs, FINALIZE_BLOCK_RUNS):  # per run: blocks of runs change no number
            runs = slice(first, first + FINALIZE_BLOCK_RUNS)
            block = state[runs]
            every = self._metrics(self.sums[runs, :n], block["dev_max"], block["dev_final"])
            steady = self._metrics(self.sums[runs, n:], block["dev_max_ss"], block["dev_final"])
            values = {**every, **{name + STEADY: values for name, values in steady.items()}}
            # every value is computed before any is written: none may still read the block's sums
            values = {name: v.copy() if np.may_share_memory(v, self.sums) else v for name, v in values.items()}
            for name in names:
                out[name][runs] = values[name]
        return out

    def _metrics(self, sums: np.ndarray, dev_max: np.ndarray, dev_final: np.ndarray) -> dict[str, np.ndarray]:
        # a sum per run and segment; a wheel's pair (``_R``, ``_L``) wheel first, (2, runs, segments), each wheel's
        # values contiguous (numpy's arithmetic on the strided pair broadcast against the count: 10x slower)
        S = {name: sums[:, :, i] for i, name in enumerate(SUMS) if not name.endswith(("_R", "_L"))}
        S.update({name[:-2]: np.stack([sums[:, :, i], sums[:, :, SUMS.index(name[:-2] + "_L")]])
                  for i, name in enumerate(SUMS) if name.endswith("_R")})
        dt = self.dt
        with np.errstate(invalid="ignore", divide="ignore"):
            n = np.where(S["count"] > 0, S["count"], np.nan)
            mean_u = S["u"] / n
            var_u = S["u2"] / n - mean_u**2
            hf = np.where(var_u > 1e-12 * np.maximum(S["u2"] / n, 1e-300), S["u_hp2"] / n / var_u, 0.0)
            chat = S["abs_du"] / n / dt
            out = {
                "deviation_mae": S["dev"] / n,
                "deviation_rmse": np.sqrt(S["dev2"] / n),
                "e_x_mae": S["abs_ex"] / n,
                "e_y_mae": S["abs_ey"] / n,
                "e_theta_mae": S["abs_eth"] / n,
                "iae": S["dev"] * dt,
                "ise": S["dev2"] * dt,
                "itae": S["tdev"] * dt,
                "chattering": _wheel_mean(chat),
                "chattering_right": chat[0],
                "chattering_left": chat[1],
                "hf_fraction": _wheel_mean(hf),
                "mean_voltage": _wheel_mean(S["abs_u"] / n),
                "energy_u2": _wheel_sum(S["u2"]) * dt,
                "electrical_energy": _wheel_sum(S["power"]) * dt,
                "saturation_fraction": S["saturated"] / n,
                "d_est_mae": _wheel_mean(S["abs_dtilde"] / n),
                "d_est_mae_ndo": _wheel_mean(S["abs_dtilde_ndo"] / n),
                "s_mae": _wheel_mean(S["abs_s"] / n),
            }
        total_only = {"deviation_max": np.where(np.isfinite(dev_max), dev_max, np.nan),
                      "deviation_final": np.where(S["count"][:, 0] > 0, dev_final, np.nan)}
        for key, val in total_only.items():
            arr = np.full((len(dev_max), len(self.segments)), np.nan)
            arr[:, 0] = val
            out[key] = arr
        return {k: out[k] for k in METRICS}
