"""The operator side: the master node, the surgeon-console logic (deadman, clutch, alignment), motion scaling and
force mapping with the passivity controller, the haptic-device registry and its drivers (HID, evdev, vendor SDKs, the
scripted operator).

Floor 2: it imports :mod:`estimator` and :mod:`teleop`, never :mod:`slave`, :mod:`study` or :mod:`live`.
"""
