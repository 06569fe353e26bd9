"""Simulated camera networks: scenes, geometric observations with ground truth, rendered videos."""

from calibproj.simulate.geometric import GeometricSimulation, simulate_tracks
from calibproj.simulate.scene import Camera, Floor, Photometric, Projector, Scene, load_scene, read_scene, save_scene

__all__ = [
    "Camera",
    "Floor",
    "GeometricSimulation",
    "Photometric",
    "Projector",
    "Scene",
    "load_scene",
    "read_scene",
    "save_scene",
    "simulate_tracks",
]
