"""Solving the discrete model: the driver (one code path for every backend), the backend
protocol and registry, CG over an operator and a preconditioner, the pyamg reference
backend, the memory guard, warm starts and the result."""
