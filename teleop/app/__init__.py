"""The application floor (ARCHITECTURE.md, "Layout"): commands that wire the sides together and may
import master/ and slave/ (tests/test_layering.py). ``teleop.app.replay``: ``teleop replay``."""
