"""The meshcat viewer of a mechanism's deflection, and its static export."""
