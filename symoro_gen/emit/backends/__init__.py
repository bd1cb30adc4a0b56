"""Code backends: each prints an optimised :class:`~symoro_gen.dynamics.graph.ExprGraph` directly.

* :mod:`.numpy` -- vectorised Python kernels ``kernel(q, dq, ddq, out)`` over (n, M) arrays;
* :mod:`.c` -- one C file of batch kernels (SIMD lanes + scalar remainder);
* :mod:`.casadi` -- a CasADi ``SX`` construction, printed as Python or built in memory.
"""
