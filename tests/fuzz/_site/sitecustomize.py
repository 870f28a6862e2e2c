"""Installs the fault wrappers of tests/fuzz/_faults.py in a `vehid` child process of the `diskfull` family."""

import importlib.util
import os

if os.environ.get("VEHID_FUZZ_FAULT"):
    _path = os.path.join(os.path.dirname(__file__), "..", "_faults.py")
    _spec = importlib.util.spec_from_file_location("_vehid_fuzz_faults", _path)
    _module = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(_module)
    _module.install()
