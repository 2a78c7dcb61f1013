# pinocchio's Python bindings are compiled and ship no type stubs, so pyright cannot see their attributes.
# This partial stub types every attribute of the package as Any (submodules still resolve to the package).
from typing import Any

def __getattr__(name: str) -> Any: ...
