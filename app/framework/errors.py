"""Exceptions raised by the recognition framework; each names what was wrong."""


class FrameworkError(ValueError):
    """Base class: bad input to a recognizer or a bundle."""


class InputShapeError(FrameworkError):
    """Samples do not have the model's input shape."""


class NonFiniteInputError(FrameworkError):
    """Samples contain NaN or infinity."""


class AttributeVectorError(FrameworkError):
    """An attribute vector has the wrong length, values other than 0/1, or names an unknown
    attribute."""


class DuplicateClassError(FrameworkError):
    """A class name, or a class's attribute vector, already exists."""


class UnknownClassError(FrameworkError, KeyError):
    """A class name the model does not know."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class NotFittedError(FrameworkError):
    """The recognizer has not been fitted yet."""


class BundleError(FrameworkError):
    """A model bundle is corrupt, truncated, or of an incompatible format version."""


class UnsupportedOperationError(FrameworkError):
    """The method cannot do this (e.g. drop its novel classes without being fitted again)."""


class InputKindError(InputShapeError):
    """Input of the wrong kind for the model: raw BioTac trials given to a model of
    fixed-shape samples, or samples that are not its tactile images given to a model fitted
    on raw trials. The message says which input the model takes."""


class TrialInputError(InputShapeError):
    """A raw trial given for recognition or enrolment is malformed. ``trial``, ``finger``
    and ``channel`` say where (None where they do not apply), ``reason`` what, as the
    ``RawTrialError`` it comes from (``__cause__``) says; ``field`` names the place in a
    request's ``trials`` list (``trials[2].fingers[1].pac``)."""

    def __init__(
        self,
        message: str,
        *,
        reason: str = "",
        trial: int | None = None,
        finger: int | None = None,
        channel: str | None = None,
    ) -> None:
        super().__init__(message)
        self.reason, self.trial, self.finger, self.channel = reason, trial, finger, channel
        place = "trials"
        if trial is not None:
            place += f"[{trial}]"
            if finger is not None:
                place += f".fingers[{finger}]"
            if channel is not None:
                place += f".{channel}"
        self.field = place


class ZeroShotUnavailableError(UnsupportedOperationError):
    """A class cannot be enrolled from a description: the model was fitted on objects
    without attributes, so it has no attribute to recognise a class by; enrol it from real
    samples instead."""


class MissingProcedureError(InputShapeError, NonFiniteInputError):
    """A sample lacks every procedure, lacks part of one, or lacks one where the model
    answers only from every procedure (or takes only complete samples, as enrolment does).
    A missing value is NaN, so this is also a ``NonFiniteInputError``: code that refuses
    NaN samples catches it unchanged."""


class TableError(FrameworkError):
    """A table of objects to name jointly (``app.framework.tables``) is malformed: object
    labels of the wrong length or kind, or a scoring option out of range."""
