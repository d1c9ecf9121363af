"""Primary rays and tracing: the pinhole camera (:mod:`subtrace.camera`) and kernels."""

from subtrace.camera import Camera, auto_camera, camera_frame, ray_direction

__all__ = ["Camera", "auto_camera", "camera_frame", "ray_direction"]
