"""Exceptions raised by the recognition framework; each names what was wrong."""


class FrameworkError(ValueError):
    """Base class: bad input to a recognizer or a bundle."""


class InputShapeError(FrameworkError):
    """Samples do not have the model's input shape."""


class NonFiniteInputError(FrameworkError):
    """Samples contain NaN or infinity."""


class AttributeVectorError(FrameworkError):
    """An attribute vector has the wrong length, values other than 0/1, or names an unknown attribute."""


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
