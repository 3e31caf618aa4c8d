"""Simulation of the paper's experiment and of YAML scenarios with faults."""

from fgloc.sim.simulate import DEFAULT_SCENARIO, SimResult, load_scenario, run_scenario, simulate_paper, write_sim

__all__ = ["DEFAULT_SCENARIO", "SimResult", "load_scenario", "run_scenario", "simulate_paper", "write_sim"]
