"""Verification beyond co-simulation: the formal properties and their SymbiYosys runs, mutation
testing, and the explicit-state equivalence search."""
