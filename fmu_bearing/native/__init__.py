"""Native part of the FMUs: the loader library that native FMI hosts load (``loader.c``) and its build
(``build.py``). Build-time only: this package is not packed into the FMUs' resources."""
