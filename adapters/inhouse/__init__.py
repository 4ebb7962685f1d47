"""The in-house formulation (Rouvinen 2003): its compiled kernels are cached where
:mod:`mbh._harness.common.kernel_cache` places them, set up here before any of its modules loads."""

from mbh._harness.common import kernel_cache

kernel_cache.install()
