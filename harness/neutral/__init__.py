"""The harness's own kinematics and dynamics, written independently of every contestant:
the joint equations on body states (``equations``, compiled in ``equation_kernels``), assembly by
Newton–Raphson (``assembly``), rank, mobility and redundant equations (``mobility``), the
conditioning of Φ_q along a motion (``conditioning``), the one start every engine shares
(``start``) and the neutral equations of motion the branch routes integrate (``dynamics``,
compiled in ``dynamics_kernels``).

Its compiled kernels are cached where :mod:`mbh._harness.common.kernel_cache` places them, set up here
before any of its modules loads, with the two of numba's compile-time costs
:mod:`mbh._harness.common.numba_compile_speed` takes out and at the LLVM level of
:mod:`mbh._harness.common.kernel_opt_level`.

May import: :mod:`mbh._harness.common`, :mod:`mbh._harness.model`.
"""

from mbh._harness.common import kernel_cache, kernel_opt_level, numba_compile_speed

kernel_cache.install()
numba_compile_speed.install()
kernel_opt_level.install(__name__)
