"""The built-in scene files (installed as implc.scenes; see implc.scene for the format)."""
