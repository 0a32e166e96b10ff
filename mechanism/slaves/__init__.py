"""FMU slaves of the ``mechanism`` package (pythonfmu scripts, built by ``build_fmu.py``)."""
