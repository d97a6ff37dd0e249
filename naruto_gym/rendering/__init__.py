"""Pictures for people: the top-down map with the trajectory and the camera's frames
(:mod:`~naruto_gym.rendering.topdown`), the env's ``rgb_array`` render."""
