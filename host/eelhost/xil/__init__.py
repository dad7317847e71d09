"""X in the loop: the robot's firmware (native or the AVR image in simavr) driving the twin.

The native firmware binding, the simavr driver, the radio model, the one lockstep stepper, and the
virtual robot behind ``sim://``. Library code: the link layer may use it, tests drive it.
"""
