"""Pages on localhost for the lab: the live view of a run, and clicking points in a frame.

The project's OpenCV is the headless build (no windows), so what a person looks at during a run
is a web page served on 127.0.0.1 by :mod:`eelhost.web.server` and opened in any browser:
``liveview`` (the camera frame with the markers found, the track, the waypoints and the twin's
predicted path) and ``picker`` (click the tank's corners for ``eelbot calibrate --click``).
"""
