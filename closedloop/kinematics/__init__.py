"""Kinematics of closed loops: closure rows and Jacobians, configurations,
assembly, joint limits."""
