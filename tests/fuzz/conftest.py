"""Hypothesis profiles for the fuzz suite.

``ci`` (the default) is derandomized, so every run tries the same cases and a failure
reproduces; ``deep`` (FACEDYN_FUZZ_PROFILE=deep) draws many more random cases for a longer
hunt and prints a failure's reproduction blob. Neither writes an example database into
the checkout. See the counts with ``--hypothesis-show-statistics``.
"""
import os

from hypothesis import HealthCheck, settings

_COMMON = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.register_profile("ci", max_examples=120, derandomize=True, database=None, **_COMMON)
settings.register_profile("deep", max_examples=2000, database=None, print_blob=True, **_COMMON)
settings.load_profile(os.environ.get("FACEDYN_FUZZ_PROFILE", "ci"))
