"""Simulation: truths and measurements drawn per Monte Carlo run, batched over runs.

- :mod:`~trackkit.sim.streams`: ``run_rng(seed, r)``, the one random stream of run r.
- :mod:`~trackkit.sim.kinematics`: platform legs (straight, turns) for targets and observers.
- :mod:`~trackkit.sim.scene`: multi-target scenes (births, deaths, clutter, detection).
- :mod:`~trackkit.sim.virtual_radar`: a rotating radar's plots of recorded AIS or ADS-B tracks.
- :mod:`~trackkit.sim.sensor_network`: asynchronous bearings of moving agents.
- :mod:`~trackkit.sim.gnss`: GPS and INS records of a vessel's truth.
- :mod:`~trackkit.sim.seatrials`: the standard manoeuvring trials of a vessel model.
"""
