"""Hypothesis profiles of the property-based suites.

``ci`` (the default) runs a fixed number of examples per test, derandomized, so that every run
draws the same examples and the suites stay inside their time budget on two cores; ``dev``
draws more examples at random, for a local hunt. ``HYPOTHESIS_PROFILE=dev pytest
tests/property`` picks it.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci",
    max_examples=12,
    derandomize=True,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.register_profile(
    "dev",
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
