"""Experiment drivers: the Monte Carlo comparisons, campaigns and identifications that
``trackkit run``, ``sweep``, ``network`` and ``identify`` run, over the scenarios of
:mod:`trackkit.scenario` and the metrics of :mod:`trackkit.eval`.

    from trackkit.experiments.compare import compare
    result = compare(trackkit.scenario.load("bo-cv"))   # tune if asked, then the Monte Carlo

- :mod:`~trackkit.experiments.montecarlo`, :mod:`~trackkit.experiments.compare`,
  :mod:`~trackkit.experiments.tuning`: filters on a single-target scenario, against the PCRLB;
  :mod:`~trackkit.experiments.results` is what they produce (the contract with the reports).
- :mod:`~trackkit.experiments.tracking_mc`, :mod:`~trackkit.experiments.tracking_run`:
  multi-target trackers on a simulated scene.
- :mod:`~trackkit.experiments.network_mc`, :mod:`~trackkit.experiments.network_compare`: the
  bearings-only agent network.
- :mod:`~trackkit.experiments.vessel_mc`: vessel identification and the IMO trials.
- :mod:`~trackkit.experiments.sweep`, :mod:`~trackkit.experiments.checkpoint`,
  :mod:`~trackkit.experiments.safestore`, :mod:`~trackkit.experiments.executors`: campaigns over
  scenario fields, their resumable store, and where the blocks run (here or on Dask).
"""
