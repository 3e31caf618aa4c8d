"""Library functions behind the commands: a typed request in, a typed result out.

The CLI (:mod:`fgloc.commands`) only parses arguments and prints; tests, tools and
``fgloc batch`` call these directly.

* :func:`fgloc.app.run.run_log` - localize one log (``fgloc run``).
"""
