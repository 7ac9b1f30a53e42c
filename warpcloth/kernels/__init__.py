"""Warp kernels of warpcloth, grouped by physics concern.

Each module holds ``@wp.func`` math and thin ``@wp.kernel`` wrappers; no Python control flow.
Installed as ``warpcloth.kernels``.
"""
