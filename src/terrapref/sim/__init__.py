"""The closed loop: vehicle at 30 Hz, camera frames at 10 Hz, drivers, and a Gymnasium environment."""

from terrapref.sim.loop import Driver, EpisodeLog, Frame, SimConfig, Simulation, run_episode

__all__ = ["Driver", "EpisodeLog", "Frame", "SimConfig", "Simulation", "run_episode"]
