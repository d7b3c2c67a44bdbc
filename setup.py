"""Build of the tracker's optional C extension; everything else is in pyproject.toml.

The tracker's per-measurement checks and common Kalman round run in C when this builds, and
in NumPy, bit for bit the same, when it does not (no compiler): ``optional=True`` turns a
failed build into a warning.
CI requires it (``GCS_UTM_REQUIRE_C=1`` in ``.ci/run``). ``-ffp-contract=off``: no fused
multiply-add, so the C arithmetic is the NumPy arithmetic.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "gcs_utm.core.tracking._kalman_c",
            sources=["gcs_utm/core/tracking/_kalman_c.c"],
            extra_compile_args=["-ffp-contract=off"],
            optional=True,
        )
    ]
)
