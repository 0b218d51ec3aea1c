"""Camera and rendering: the forward camera, render workers, the MJPEG server, the video feed process."""
