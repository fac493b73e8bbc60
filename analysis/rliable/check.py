"""rliable 1.2.0's own figures for the data idrex's test gives it (tests/rliable.rs).

Reads {"x": [...], "y": [...], "reps": N} on stdin: one score per replicate of two methods,
one task. Prints JSON: aggregate IQM of x with its stratified-bootstrap interval, and the
probability of improvement of x over y with its independent-bootstrap interval, each from
rliable's functions (percentile intervals, as idrex reports).
"""
import json
import sys
import warnings

import numpy as np
from rliable import library, metrics

warnings.filterwarnings("ignore")
data = json.load(sys.stdin)
x = np.array(data["x"], dtype=float).reshape(-1, 1)
y = np.array(data["y"], dtype=float).reshape(-1, 1)
reps = int(data["reps"])
_, iqm_ci = library.get_interval_estimates(
    {"x": x}, lambda s: np.array([metrics.aggregate_iqm(s)]), reps=reps, random_state=np.random.RandomState(0)
)
_, poi_ci = library.get_interval_estimates(
    {"xy": [x, y]},
    lambda a, b: np.array([metrics.probability_of_improvement(a, b)]),
    reps=reps,
    random_state=np.random.RandomState(0),
)
print(
    json.dumps(
        {
            "iqm": float(metrics.aggregate_iqm(x)),
            "iqm_ci": [float(poi) for poi in iqm_ci["x"][:, 0]],
            "poi": float(metrics.probability_of_improvement(x, y)),
            "poi_ci": [float(v) for v in poi_ci["xy"][:, 0]],
        }
    )
)
