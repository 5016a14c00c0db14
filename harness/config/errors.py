"""`ConfigError`: every invalid user input, raised before anything runs, as one line
``<dotted field> = <value>: <what is allowed>`` (the CLI prints ``error: ...`` and exits 2)."""

from __future__ import annotations

from typing import Any


def short_repr(value: Any, limit: int = 80) -> str:
    """`repr(value)` on one line, shortened to about `limit` characters."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


class ConfigError(ValueError):
    """Invalid configuration, one line; `path`: the dotted field, `value`: its value (None: not known)."""

    def __init__(self, message: str, *, path: str | None = None, value: Any = None) -> None:
        super().__init__(" ".join(str(message).splitlines()))
        self.path, self.value = path, value

    @classmethod
    def field(cls, path: str, value: Any, expected: str) -> ConfigError:
        return cls(f"{path} = {short_repr(value)}: {expected}", path=path, value=value)

    def with_context(self, context: str) -> ConfigError:
        """A copy prefixed (`context: message`) or, for a context in parentheses, suffixed."""
        msg = f"{self} {context}" if context.startswith("(") else f"{context}: {self}"
        return ConfigError(msg, path=self.path, value=self.value)


__all__ = ["ConfigError", "short_repr"]
