"""The ``egc-teleop`` console script: argument parsing and the wiring of the packages (DESIGN 2).

It may import every package and ``egc_experiments``; nothing imports it (tests run it as a
process, ``python -m egc_app.cli``). Each module is a subcommand, ``configure(parser)`` and
``run(args)``; what does the work lives in the packages (``tests/test_layout.py`` checks both).
"""
