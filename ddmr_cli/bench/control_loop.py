"""The template of the loop that times a controller's laws alone (:mod:`ddmr_cli.bench.cost`): a controller's
``start``, then per control step ``command`` and ``update``, on one state record.

It takes the controller's laws from the controller slot as the step loop does
(:mod:`ddmr_cli.engine.controller_slot`), so :func:`ddmr_cli.engine.kernels.compiled_copy` makes one copy per
controller, with these import lines pointed at the controller's module, and caches its compiled code on disk: a
later process loads it instead of compiling the laws again (2-5 s a controller).
"""

from __future__ import annotations

from ddmr_cli.compiled import law
from ddmr_cli.engine.controller_slot import command as controller_command  # controller laws
from ddmr_cli.engine.controller_slot import start as controller_start  # controller laws
from ddmr_cli.engine.controller_slot import update as controller_update  # controller laws


@law
def control_steps(p, state, w, wd, wdd):
    """Run the controller's laws for ``len(w)`` control steps on ``state[0]``: ``start``, then per step ``command``
    on ``(w[i], wd[i], wdd[i])`` (both wheels) and ``update`` with the voltage it returned. Returns the sum of the
    voltages (so that nothing is optimised away)."""
    st = state[0]
    controller_start(p, st, w[0, 0], w[0, 1])
    total = 0.0
    for i in range(w.shape[0]):
        u_R, u_L = controller_command(p, st, i, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], wdd[i, 0], wdd[i, 1])
        controller_update(p, st, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], u_R, u_L, u_R, u_L, False, False)
        total += u_R + u_L
    return total


__all__ = ["control_steps"]
