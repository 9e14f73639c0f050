"""A plug-in file that cannot be imported."""

import this_module_does_not_exist  # noqa: F401
