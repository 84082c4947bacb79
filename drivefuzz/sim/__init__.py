"""Running a scenario: the per-tick order (:mod:`~drivefuzz.sim.execute`), the world read from SUMO
(:mod:`~drivefuzz.sim.world`), the ego's vehicle physics (:mod:`~drivefuzz.sim.physics`), the frozen
:class:`~drivefuzz.sim.trace.Trace`, and the crash-isolating simulation host (:mod:`~drivefuzz.sim.simhost`).

Only this package imports libsumo.
"""
