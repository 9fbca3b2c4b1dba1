"""Elastostatics: spring factors, the compliance (unloaded, preloaded, many
configurations at once), tangent stiffness, nonlinear statics."""
