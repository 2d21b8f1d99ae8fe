"""The built-in domains, one plugin module each, and the registry's names (:mod:`torchrl_subgoal.registry`).

``from torchrl_subgoal import domains`` gives the registry (``domains.get``,
``domains.register``, ``domains.Domain`` …); it imports no plugin. Each plugin
module here is imported the first time its domain is looked up by name.
"""

from torchrl_subgoal.registry import (
    PLUGINS,
    Domain,
    UnknownDomainError,
    find,
    get,
    having,
    load_pattern,
    load_patterns,
    names,
    part,
    register,
    subgoal_check,
)

__all__ = [
    "PLUGINS",
    "Domain",
    "UnknownDomainError",
    "find",
    "get",
    "having",
    "load_pattern",
    "load_patterns",
    "names",
    "part",
    "register",
    "subgoal_check",
]
