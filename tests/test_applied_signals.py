"""Issue 25 §1: laws read signals after the actuator model (the ADRC's reported estimate of d under the applied,
saturated and PWM-quantised voltage)."""
from __future__ import annotations

import numpy as np

from ddmr_cli import paper_simulation, simulate
from ddmr_cli.compiled import plain
from ddmr_cli.control import adrc
from ddmr_cli.model.robot import NominalModel


def test_adrcs_reported_estimate_is_the_esos_under_the_applied_voltage_when_saturated():
    """ADRC on scenario 1 (15 s) with U_max = 12 V and 8-bit PWM: replaying the ESO (eso_step, the applied u_k = the
    motor's voltage series, ideal sensor, control rate = plant rate) gives z2_k; the reported estimate must be
    z2_k - (f(w_k) + (g - b0) u_k) with the applied u_k at every step (docs/model.md §6). The run saturates (a third of the steps).
    """
    s = paper_simulation("controller=adrc", "robot.max_voltage=12.0", "actuator=pwm8")
    r = simulate(s, [0], keep_series=[0]).series[0]
    nominal = NominalModel.from_robot(s.robot)
    p = s.controller.law_parameters(nominal, s.dt)
    w_R, w_L, u_R, u_L = r["w_right"], r["w_left"], r["u_right"], r["u_left"]
    assert np.mean(np.abs(r["u_command_right"]) > 12.0) > 0.05  # a case that saturates
    assert not np.allclose(u_R, np.clip(r["u_command_right"], -12.0, 12.0))  # and PWM quantises
    st = {"z1": np.zeros(2), "z2": np.zeros(2)}
    plain(adrc.start)(p, st, w_R[0], w_L[0])
    eso, td = plain(adrc.eso_step), plain(adrc.total_disturbance)
    expected = np.empty((len(w_R), 2))
    for k in range(len(w_R)):
        f_R, f_L = td(p.nominal, p.b0, w_R[k], w_L[k], u_R[k], u_L[k])
        expected[k] = st["z2"][0] - f_R, st["z2"][1] - f_L
        st["z1"][0], st["z2"][0] = eso(st["z1"][0], st["z2"][0], w_R[k], u_R[k], p.b0, p.beta1, p.beta2, p.dt)
        st["z1"][1], st["z2"][1] = eso(st["z1"][1], st["z2"][1], w_L[k], u_L[k], p.b0, p.beta1, p.beta2, p.dt)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(r["d_hat_eso_right"], expected[:, 0], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(r["d_hat_eso_left"], expected[:, 1], rtol=0, atol=1e-9 * scale)
