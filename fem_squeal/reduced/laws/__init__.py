"""Contact and friction laws of the reduced layer, each defined once (NumPy only).

Normal laws (:mod:`.contact`): pressure as a function of the closure, with their tangent stiffness;
friction laws (:mod:`.friction`): friction coefficient or force as a function of the slip speed."""
