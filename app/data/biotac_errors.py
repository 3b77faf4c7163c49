"""``RawTrialError``: what every problem with a raw BioTac trial raises, naming where it is
(trial, file, group, finger, channel). Its own module so that the trial type
(``app.data.biotac_trial``) and the phase rule (``app.data.biotac_phases``) both raise it
without importing each other both ways."""

from __future__ import annotations

from typing import Any

from app.data.dataset import DatasetError


class RawTrialError(DatasetError):
    """A raw trial is malformed. ``trial`` (index in a batch), ``file`` and ``group`` (where
    it was read from), ``finger`` (index) and ``channel`` say where, ``reason`` what; those
    that do not apply are None, and the message names all that are set."""

    def __init__(
        self,
        reason: str,
        *,
        trial: int | None = None,
        finger: int | None = None,
        channel: str | None = None,
        file: str | None = None,
        group: str | None = None,
    ) -> None:
        self.reason, self.trial, self.finger, self.channel = reason, trial, finger, channel
        self.file, self.group = (None if file is None else str(file)), group
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.group is not None:
            where.append(f"group {self.group!r}")
        if self.trial is not None:
            where.append(f"trial {self.trial}")
        if self.finger is not None:
            where.append(f"finger {self.finger}")
        if self.channel is not None:
            where.append(f"channel {self.channel!r}")
        return f"{', '.join(where)}: {self.reason}" if where else self.reason

    def located(self, **where: Any) -> RawTrialError:
        """The same error with more of its location filled in (fields already set stay)."""
        fields = {k: getattr(self, k) for k in ("trial", "finger", "channel", "file", "group")}
        fields.update({k: v for k, v in where.items() if fields.get(k) is None})
        return RawTrialError(self.reason, **fields)
