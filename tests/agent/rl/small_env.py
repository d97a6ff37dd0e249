"""The small discrete env the explorer-family policy tests walk: one generated room, a 16 x 16
camera and the explorer's (32, 64) panorama."""

from __future__ import annotations

from naruto_gym.sensors.pinhole import PinholeCamera

ENV = {
    "action_mode": "discrete",
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "panorama_shape": (32, 64),
    "coverage_samples": 1000,
    "scene": "procedural:room:7",
}
