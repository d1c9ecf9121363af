"""Primary rays and tracing: the pinhole camera (:mod:`subtrace.trace.camera`) and kernels."""

from .camera import Camera, auto_camera, camera_frame, ray_direction

__all__ = ["Camera", "auto_camera", "camera_frame", "ray_direction"]
