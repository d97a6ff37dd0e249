"""The agent's sensors: the pinhole RGB-D camera (:mod:`~naruto_gym.sensors.pinhole`), drawn by
the rasterizer (:mod:`~naruto_gym.sensors.raster`) or by the ray caster
(:mod:`~naruto_gym.sensors.raycaster`, Embree), the equirectangular depth panorama
(:mod:`~naruto_gym.sensors.panorama`), and their compiled per-pixel loops
(:mod:`~naruto_gym.sensors.kernels`)."""
