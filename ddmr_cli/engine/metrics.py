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

from ddmr_cli.compiled import cached_law, inlined_law, law
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
    """A step's terms (:func:`step_terms`) added to a run's block of sums (a record's ``block``, or a lane's column
    of the lanes loop's rows), written out (a loop over a tuple's entries indexes it at run time: 1.5x the step
    loop's time)."""
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


#: column of each sum in a segment's row (:data:`SUMS`), for :func:`segment_metrics`
(COUNT, DEV, DEV2, TDEV, ABS_EX, ABS_EY, ABS_ETH, SATURATED, ABS_DU_R, ABS_DU_L, U2_R, U2_L, POWER_R, POWER_L,
 ABS_DTILDE_R, ABS_DTILDE_L, ABS_DTILDE_NDO_R, ABS_DTILDE_NDO_L, ABS_S_R, ABS_S_L, U_R, U_L, U_HP2_R, U_HP2_L,
 ABS_U_R, ABS_U_L) = range(N_SUMS)
#: the order in which :func:`segment_metrics` writes a segment's metrics: :data:`METRICS`'s own
SEGMENT_METRICS = ("deviation_mae", "deviation_rmse", "deviation_max", "deviation_final", "e_x_mae", "e_y_mae",
                   "e_theta_mae", "iae", "ise", "itae", "chattering", "chattering_right", "chattering_left",
                   "hf_fraction", "mean_voltage", "energy_u2", "electrical_energy", "saturation_fraction",
                   "d_est_mae", "d_est_mae_ndo", "s_mae")
if SEGMENT_METRICS != tuple(METRICS):  # pragma: no cover - a metric added to the catalog and not here
    raise ImportError("engine/metrics.py: segment_metrics writes other metrics than the catalog's METRICS")
N_METRICS = len(SEGMENT_METRICS)


@law
def high_frequency_fraction(u_hp2, u2, u, n):
    """[7a] ``hf_fraction`` of one wheel: ``mean(y^2) / var(u)``, y the high-passed voltage; 0 where var(u) is
    nil (a constant voltage) against the mean square, or the segment is empty (``n`` NaN)."""
    mean_u, mean_square = u / n, u2 / n
    var_u = mean_square - mean_u * mean_u
    floor = mean_square if mean_square > 1e-300 or math.isnan(mean_square) else 1e-300  # as numpy's maximum
    return u_hp2 / n / var_u if var_u > 1e-12 * floor else 0.0


@law
def segment_metrics(s, dt, dev_max, dev_final, whole_run, out):
    """The metrics of docs/model.md §7 of one segment from its sums ``s`` (a row of :data:`SUMS`), into ``out`` in
    the order of :data:`SEGMENT_METRICS`: the means over the segment's steps (NaN when it has none), the integrals
    (sums times ``dt``), a wheel pair's mean or sum. ``deviation_max`` and ``deviation_final`` are the whole run's
    (``whole_run``; NaN in every other segment): the largest deviation ``dev_max`` (NaN where no step counted),
    the last ``dev_final`` (NaN where the segment is empty)."""
    n = s[COUNT] if s[COUNT] > 0 else np.nan
    chattering_R, chattering_L = s[ABS_DU_R] / n / dt, s[ABS_DU_L] / n / dt
    out[0] = s[DEV] / n
    out[1] = math.sqrt(s[DEV2] / n)
    out[2] = dev_max if whole_run and math.isfinite(dev_max) else np.nan
    out[3] = dev_final if whole_run and s[COUNT] > 0 else np.nan
    out[4], out[5], out[6] = s[ABS_EX] / n, s[ABS_EY] / n, s[ABS_ETH] / n
    out[7], out[8], out[9] = s[DEV] * dt, s[DEV2] * dt, s[TDEV] * dt
    out[10], out[11], out[12] = (chattering_R + chattering_L) / 2.0, chattering_R, chattering_L
    out[13] = (high_frequency_fraction(s[U_HP2_R], s[U2_R], s[U_R], n)
               + high_frequency_fraction(s[U_HP2_L], s[U2_L], s[U_L], n)) / 2.0
    out[14] = (s[ABS_U_R] / n + s[ABS_U_L] / n) / 2.0
    out[15], out[16] = (s[U2_R] + s[U2_L]) * dt, (s[POWER_R] + s[POWER_L]) * dt
    out[17] = s[SATURATED] / n
    out[18] = (s[ABS_DTILDE_R] / n + s[ABS_DTILDE_L] / n) / 2.0
    out[19] = (s[ABS_DTILDE_NDO_R] / n + s[ABS_DTILDE_NDO_L] / n) / 2.0
    out[20] = (s[ABS_S_R] / n + s[ABS_S_L] / n) / 2.0


@cached_law
def metrics_over_sums(sums, dev_max, dev_max_ss, dev_final, dt, rows):
    """Every run's metrics (:func:`segment_metrics`, each segment over all its steps then over its steady ones)
    into ``rows[run]``: metric ``i`` (of :data:`METRICS`, then their steady twins) of segment ``j`` at column
    ``i * n_segments + j``. ``rows`` may be the sums' own memory: a run's metrics are formed in ``values`` from
    its sums before they are written over them."""
    n_runs, n_segments = sums.shape[0], sums.shape[1] // 2
    out, values = np.empty(N_METRICS), np.empty(2 * N_METRICS * n_segments)
    for r in range(n_runs):
        for half in range(2):
            largest = dev_max[r] if half == 0 else dev_max_ss[r]
            for j in range(n_segments):
                segment_metrics(sums[r, half * n_segments + j], dt, largest, dev_final[r], j == 0, out)
                for i in range(N_METRICS):
                    values[(half * N_METRICS + i) * n_segments + j] = out[i]
        for c in range(values.shape[0]):
            rows[r, c] = values[c]


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
        empty), by the compiled :func:`metrics_over_sums`. The step loop has added each run's last block to its
        segments at the run's last step (:func:`flush`).

        The metrics are written over the sums they come from (:attr:`sums` holds them afterwards: call once), a
        run at a time: a run's metrics take fewer numbers than its sums (``2 len(METRICS)`` against ``2 N_SUMS`` a
        segment), and the largest batch's memory peaks here (10,000 seeds: 17 MiB of metrics came on top of the
        20 MiB of sums). Each metric is a view ``(n_runs, n_segments)`` of that memory."""
        n, names = len(self.segments), [*METRICS, *(name + STEADY for name in METRICS)]
        rows = self.sums.reshape(self.n_runs, -1)
        if len(names) * n > rows.shape[1]:  # pragma: no cover - METRICS outgrew SUMS: separate arrays
            rows = np.empty((self.n_runs, len(names) * n))
        with np.errstate(invalid="ignore", divide="ignore"):  # the plain-Python laws (NUMBA_DISABLE_JIT=1)
            metrics_over_sums(self.sums, state["dev_max"], state["dev_max_ss"], state["dev_final"], self.dt, rows)
        return {name: rows[:, i * n:(i + 1) * n] for i, name in enumerate(names)}
