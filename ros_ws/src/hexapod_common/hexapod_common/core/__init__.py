"""The numerical core every package shares (no rclpy). Its compiled code imports numba's
compiler through jit.py (512-bit vectors on AVX-512 CPUs: vector_width.py)."""
