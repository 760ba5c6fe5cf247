"""The plants the controllers drive (docs/model.md §1, §13): the paper's wheel plant, inlined in the compiled step
loop (:mod:`ddmr_cli.plant.wheel`), and external plants stepped from Python (:mod:`ddmr_cli.plant.base`).

A plant is chosen by ``plant=<name>`` (conf/plant/<name>.yaml, whose ``name`` is the module's): the module
``ddmr_cli.plant.<name>`` defines ``factory(config)``, which returns a callable building the plant of a
simulation (:attr:`ddmr_cli.engine.simulation.Simulation.plant`); the wheel plant has none (it is the loop's own).
"""
