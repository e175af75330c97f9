"""The ``drake-tracker`` command line: parsing (``main``), argument checks and listings."""
