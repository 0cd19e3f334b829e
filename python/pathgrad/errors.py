"""pathgrad's exceptions: one class per kind of failure, each carrying the library's message."""

__all__ = ["Error", "SceneError", "ArgumentError", "UnknownParameterError", "FileError", "DeviceError", "NumericError"]


class Error(Exception):
    """The base of every exception pathgrad raises."""


class SceneError(Error):
    """A scene that cannot be loaded or rendered: the message names the file, line and element."""


class ArgumentError(Error, ValueError):
    """A bad argument: a wrong shape, dtype, name or value. The message names the argument."""


class UnknownParameterError(ArgumentError, KeyError):
    """A parameter name the scene does not have. Also a ``KeyError``, so that
    ``scene.params.get(name)`` and ``name in scene.params`` behave as for a dict."""

    def __str__(self) -> str:  # KeyError would show the message quoted
        return str(self.args[0]) if self.args else ""


class FileError(Error, OSError):
    """A file that cannot be read or written (images, scenes' resources)."""


class DeviceError(Error, RuntimeError):
    """No usable Vulkan device, or the device failed (allocation, timeout, lost device)."""


class NumericError(Error, ArithmeticError):
    """A render or gradient produced values that are not finite."""
