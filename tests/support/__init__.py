"""Plain helpers shared by the tests (importable as ``support``: pyproject.toml puts ``tests`` on the path).

Fixtures live in the ``conftest.py`` of the folder that uses them (the session-wide ones in
``tests/conftest.py``); what is here is called by module-level helpers of the tests or by child
processes that run without pytest, so it cannot be a fixture:

- :mod:`support.paths`: the repository root;
- :mod:`support.processes`: the environment of a child process (``mpirun`` included);
- :mod:`support.ring`: the ring between two plates, meshed and assembled once per process;
- :mod:`support.blocks`: two stacked blocks for the interface tests;
- :mod:`support.operators`: nodal fields as vectors, bilinear forms, projected operators;
- :mod:`support.ranks`: a test module's numbers on two ranks, and spectra compared as sets.
"""
