"""The closed-form backends: ``consistent`` (:mod:`.consistent`, the paper's formulation
made consistent with the mechanism) and ``published`` (:mod:`.published`, the paper's
matrices as printed). The ``generic`` backend is :mod:`closedloop` on the Pinocchio model;
the registry of the three is :mod:`cahyman_pin.backends.registry`."""
