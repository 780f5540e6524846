"""The application layer: scene schema, pipeline and stage cache, the analyses' stages, report,
plots and command line.  Imports every layer below it (``fe``, ``reduced``, ``util``, ``geometry``)."""
