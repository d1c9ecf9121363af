"""Helpers for projects that test their renders with subtrace: :mod:`subtrace.testing.plugin`,
the pytest plugin of golden-image tests (registered as the ``pytest11`` entry point
``subtrace``, so installing subtrace installs it). Importing this package imports nothing
but the standard library and pytest."""
