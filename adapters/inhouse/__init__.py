"""The in-house formulation (Rouvinen 2003): its compiled kernels are cached where
:mod:`mbh._harness.common.kernel_cache` places them, set up here before any of its modules loads,
with the two of numba's compile-time costs :mod:`mbh._harness.common.numba_compile_speed` takes
out and at the LLVM level of :mod:`mbh._harness.common.kernel_opt_level`."""

from mbh._harness.common import kernel_cache, kernel_opt_level, numba_compile_speed

kernel_cache.install()
numba_compile_speed.install()
kernel_opt_level.install(__name__)
