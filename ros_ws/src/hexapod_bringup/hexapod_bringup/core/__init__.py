"""hexapod_bringup's numerical core (no rclpy). Compiled code imports numba through
hexapod_common.core.jit (512-bit vectors on AVX-512 CPUs)."""
