"""Many runs on Dask: Monte Carlo campaigns of the estimators on a simulated scenario (`gtsam-dvl montecarlo`)
and fleet processing of many logs with one configuration (`gtsam-dvl smooth LOG... --out-dir`).

Modules: montecarlo.py (one seed's run as plain data, a campaign's statistics), runner.py (the campaign: tasks
per seed, retry, resume), report.py (report.md and figures), fleet.py (many logs), cluster.py (the Dask client).
"""
