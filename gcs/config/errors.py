"""ConfigError: the one error every team-file problem raises (re-exported by gcs.config.schema)."""

from __future__ import annotations


class ConfigError(ValueError):
    """A bad team config. str(e) is one line: "<file>: <key path>: <problem>[ (line N)]".

    ConfigError(message) with a single argument is accepted too; then only str(e) is meaningful.
    """

    def __init__(
        self,
        source: str,
        path: str | None = None,
        problem: str | None = None,
        line: int | None = None,
    ) -> None:
        if path is None or problem is None:
            message = source
        else:
            message = f"{source}: {path}: {problem}" + (f" (line {line})" if line else "")
        super().__init__(" ".join(message.splitlines()))
        self.source, self.path, self.problem, self.line = source, path, problem, line
