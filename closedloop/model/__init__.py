"""The closed-loop model: a Pinocchio model with loop closures, actuated joints and
springs; beams, ball joints, elastic energy, gravity and payloads."""
