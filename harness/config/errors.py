"""Exceptions shared by the harness.

`ConfigError` is raised for every invalid user input (scenario, bounds or study file, command-line
value) *before* any simulation starts.  Its message is a single line naming the dotted field path,
the offending value and the allowed range or type, e.g.::

    plant.segments = 100: must be an integer in [1, 64]

The command-line interface (`harness.cli`) turns `ConfigError` (and `controllers.params.ParameterError`
and the plant builder's `PlantModelError`) into exit status 2 with a one-line ``error: ...`` message.
"""

from __future__ import annotations

from typing import Any

_MISSING = object()


def short_repr(value: Any, limit: int = 80) -> str:
    """`repr(value)` on one line, shortened to about `limit` characters."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


class ConfigError(ValueError):
    """Invalid configuration.  One line: ``<path> = <value>: <what is allowed>``.

    `ConfigError(message)` takes a ready message; `ConfigError.field(path, value, expected)` builds
    the standard one.  `path` and `value` are kept as attributes (None / absent when not applicable).
    """

    def __init__(self, message: str, *, path: str | None = None, value: Any = _MISSING) -> None:
        super().__init__(" ".join(str(message).splitlines()))
        self.path = path
        self.value = None if value is _MISSING else value
        self.has_value = value is not _MISSING

    @classmethod
    def field(cls, path: str, value: Any, expected: str) -> ConfigError:
        return cls(f"{path} = {short_repr(value)}: {expected}", path=path, value=value)

    def with_context(self, context: str) -> ConfigError:
        """A copy whose message is prefixed (`context: message`) or suffixed (`message (context)`)."""
        if context.startswith("("):
            msg = f"{self} {context}"
        else:
            msg = f"{context}: {self}"
        err = ConfigError(msg, path=self.path)
        err.value, err.has_value = self.value, self.has_value
        return err


__all__ = ["ConfigError", "short_repr"]
