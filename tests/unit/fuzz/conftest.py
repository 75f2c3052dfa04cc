"""Hypothesis profiles for the property-based tests: bounded so the whole set stays near a minute.

`HYPOTHESIS_PROFILE=deep` explores much longer (by hand, not in CI); `quick` (what
`./dev test --quick` sets, the inner loop) runs every property on fewer examples.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci",
    max_examples=300,
    deadline=None,  # a slow example is not a failure: CI machines are shared
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "quick",
    max_examples=50,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "deep",
    max_examples=5_000,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
