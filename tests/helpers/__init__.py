"""Helpers shared by the tests: the simulators on this machine, the ADC bench harness, the
expected values worked out apart from the code under test."""
