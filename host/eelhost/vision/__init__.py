"""Vision: localise the robot from its printed markers in overhead frames.

Modules: ``markers`` (marker layout, printable sheet), ``calibration`` (pixels <-> metres),
``localise`` (per-frame pose), ``sources`` (camera, video, image folder, synthetic frames) and
``synthetic`` (the synthetic overhead camera of the twin, with ground truth).
"""
