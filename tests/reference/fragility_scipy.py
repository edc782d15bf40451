"""Reference lognormal fragility fit by maximum likelihood with scipy (Baker 2015).

Writes fragility_scipy.json: a fixed set of (intensity, overturned) outcomes drawn from a known
lognormal curve, and the MLE (median, beta, log-likelihood) that scipy.optimize finds for it.
shakeflow's Newton/probit fit (src/stats/fragility.rs) must agree (tests/fragility_scipy.rs).

    python tests/reference/fragility_scipy.py > tests/reference/fragility_scipy.json
"""
import json
import sys

import numpy as np
import scipy
from scipy import optimize, stats

rng = np.random.default_rng(20240517)
levels = np.geomspace(0.5, 8.0, 12)          # m/s^2, like a PFA grid
im = np.repeat(levels, 15)
true_median, true_beta = 2.4, 0.45
overturned = rng.random(im.size) < stats.norm.cdf(np.log(im / true_median) / true_beta)


def negative_log_likelihood(params):
    ln_median, ln_beta = params
    z = (np.log(im) - ln_median) / np.exp(ln_beta)
    return -(stats.norm.logcdf(z[overturned]).sum() + stats.norm.logcdf(-z[~overturned]).sum())


result = optimize.minimize(negative_log_likelihood, x0=[np.log(2.0), np.log(0.5)], method="Nelder-Mead",
                           options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000})
assert result.success, result.message
json.dump({
    "source": "tests/reference/fragility_scipy.py (scipy.optimize.minimize Nelder-Mead on the lognormal likelihood)",
    "scipy_version": scipy.__version__,
    "im": im.tolist(),
    "overturned": overturned.astype(bool).tolist(),
    "median": float(np.exp(result.x[0])),
    "beta": float(np.exp(result.x[1])),
    "log_likelihood": float(-result.fun),
}, sys.stdout, indent=1)
print()
