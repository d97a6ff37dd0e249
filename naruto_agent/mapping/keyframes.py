"""The keyframe ray store: the pixels each keyframe keeps, and random draws across them."""

from __future__ import annotations

import torch

from naruto_agent.mapping.rendering import RayBatch


class KeyframeRays:
    """Rays kept from keyframes (5 % of each keyframe's pixels in the published system).

    Each stored ray is its camera-frame direction (z = 1), colour, depth and keyframe number;
    world rays are made on drawing, from the keyframe's pose. Buffers grow by doubling, so
    adding a keyframe costs amortised O(its rays).
    """

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self.count = 0
        self._directions = torch.empty(0, 3, device=device)
        self._rgb = torch.empty(0, 3, dtype=torch.uint8, device=device)
        self._depth = torch.empty(0, device=device)
        self._keyframe = torch.empty(0, dtype=torch.int32, device=device)
        self._poses: list[torch.Tensor] = []
        self._pose_tensor: torch.Tensor | None = None

    @property
    def num_keyframes(self) -> int:
        return len(self._poses)

    def _grow(self, needed: int) -> None:
        capacity = self._depth.shape[0]
        if needed <= capacity:
            return
        new_capacity = max(needed, 2 * capacity, 1024)

        def grown(buffer: torch.Tensor) -> torch.Tensor:
            bigger = torch.empty(
                (new_capacity, *buffer.shape[1:]), dtype=buffer.dtype, device=buffer.device
            )
            bigger[: self.count] = buffer[: self.count]
            return bigger

        self._directions = grown(self._directions)
        self._rgb = grown(self._rgb)
        self._depth = grown(self._depth)
        self._keyframe = grown(self._keyframe)

    def add(
        self,
        camera_to_world: torch.Tensor,
        directions_camera: torch.Tensor,
        rgb: torch.Tensor,
        depth: torch.Tensor,
    ) -> None:
        """Store one keyframe's rays: (4, 4) pose, (K, 3) directions, (K, 3) uint8, (K,)."""
        k = int(depth.shape[0])
        self._grow(self.count + k)
        end = self.count + k
        self._directions[self.count : end] = directions_camera.to(self.device)
        self._rgb[self.count : end] = rgb.to(self.device)
        self._depth[self.count : end] = depth.to(self.device)
        self._keyframe[self.count : end] = len(self._poses)
        self._poses.append(camera_to_world.to(self.device, torch.float32))
        self._pose_tensor = None
        self.count = end

    def poses(self) -> torch.Tensor:
        """(K, 4, 4) keyframe poses."""
        if self._pose_tensor is None:
            self._pose_tensor = torch.stack(self._poses)
        return self._pose_tensor

    def sample(self, count: int, generator: torch.Generator | None) -> RayBatch:
        """``count`` rays drawn uniformly (with replacement) from all stored rays."""
        if self.count == 0:
            raise ValueError("no keyframe rays stored yet; integrate a frame first")
        index = torch.randint(
            0, self.count, (count,), device=self.device, generator=generator
        )
        pose = self.poses()[self._keyframe[index].long()]
        directions = torch.einsum("nij,nj->ni", pose[:, :3, :3], self._directions[index])
        return RayBatch(
            origins=pose[:, :3, 3],
            directions=directions,
            rgb=self._rgb[index].float() / 255.0,
            depth=self._depth[index],
        )

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {
            "directions": self._directions[: self.count].cpu(),
            "rgb": self._rgb[: self.count].cpu(),
            "depth": self._depth[: self.count].cpu(),
            "keyframe": self._keyframe[: self.count].cpu(),
            "poses": self.poses().cpu() if self._poses else torch.empty(0, 4, 4),
        }

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.count = int(state["depth"].shape[0])
        self._directions = state["directions"].to(self.device)
        self._rgb = state["rgb"].to(self.device)
        self._depth = state["depth"].to(self.device)
        self._keyframe = state["keyframe"].to(self.device)
        self._poses = [pose.to(self.device) for pose in state["poses"]]
        self._pose_tensor = None
