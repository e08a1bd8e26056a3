"""The lecture's models in numpy: systems, solvers, forces, particles.

Imports no physics engine and nothing of the harness.
"""
