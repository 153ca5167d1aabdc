"""Exceptions with messages that name the offending input."""


class PushToKnowError(Exception):
    """Base class of every error the project raises on purpose."""


def first_line(e: BaseException) -> str:
    """The first non-empty line of an exception's message (a library's explanation can run over
    many lines; a one-line error keeps its head)."""
    return next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)


def yaml_error_summary(e: Exception) -> str:
    """'not valid JSON/YAML (line N: problem)' for a yaml.YAMLError."""
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None) or first_line(e)
    return (
        f"not valid JSON/YAML (line {mark.line + 1}: {problem})"
        if mark
        else f"not valid JSON/YAML ({problem})"
    )


VALUE_CHARS = 300  # the longest value an error message shows (a file path fits whole)


class ObjectSpecError(PushToKnowError, ValueError):
    """An object description is invalid; the message names the field and the value."""

    def __init__(self, field: str, value: object, problem: str):
        self.field, self.value, self.problem = field, value, problem
        shown = repr(value)
        if len(shown) > VALUE_CHARS:  # a whole file read as one value stays one line
            shown = f"{shown[: VALUE_CHARS - 1]}…"
        super().__init__(f"invalid object spec: {field}={shown}: {problem}")

    def __reduce__(self):  # raised in a worker process, re-raised in the parent
        return type(self), (self.field, self.value, self.problem)


class DatasetError(PushToKnowError):
    """A dataset file is corrupt, of another schema version, or otherwise unreadable."""

    def __init__(self, path: object, problem: str):
        self.path, self.problem = path, problem
        super().__init__(f"{path}: {problem}")

    def __reduce__(self):  # raised in a worker process, re-raised in the parent
        return type(self), (self.path, self.problem)


class DiskFullError(PushToKnowError):
    """The disk filled up while a file was written; the message names the file. Files written
    atomically (`common.files`) keep their previous content."""

    def __init__(self, path: object):
        self.path = path
        super().__init__(
            f"disk full writing {path} (no space left on device); free some space and run the "
            "command again"
        )

    def __reduce__(self):
        return type(self), (self.path,)


class PushToKnowWarning(UserWarning):
    """A caution about the input that does not stop the work (an incomplete dataset, data
    overlapping what is evaluated); the command line prints it as one 'warning:' line."""


class ConfigError(PushToKnowError, ValueError):
    """A configuration file is not valid YAML or not a valid config; the message names the
    file and each offending field."""

    def __init__(self, path: object, problem: str):
        self.path, self.problem = path, problem
        super().__init__(f"{path}: {problem}")

    def __reduce__(self):
        return type(self), (self.path, self.problem)


class RenderingUnavailableError(PushToKnowError, RuntimeError):
    """Headless OpenGL could not be initialised."""


class ShapeError(PushToKnowError, ValueError):
    """A tensor has the wrong shape; the message gives expected and received shapes."""


class CheckpointError(PushToKnowError):
    """A checkpoint is missing or was written by an incompatible version or config."""


class TestbedVersionError(PushToKnowError, ValueError):
    """Data or a model come from another physics version of the testbed than this one."""

    __test__ = False  # not a pytest test class despite its name


class UntrainedProfileError(PushToKnowError, ValueError):
    """Inference asked for a speed profile the model was never trained on."""


class IdentificationError(PushToKnowError, ValueError):
    """Physics-based identification cannot run on the input it was given (no pushes, no
    footprint, a pusher track the simulator cannot replay); the message names the problem."""


class ClusterError(PushToKnowError, RuntimeError):
    """A Ray cluster is unavailable (Ray not installed, or the address unreachable)."""


class ExportError(PushToKnowError, ValueError):
    """An object cannot be exported for another simulator (an invalid parameter or outline, or
    an unwritable path); the message names the field and the value."""

    def __init__(self, field: str, value: object, problem: str):
        self.field, self.value, self.problem = field, value, problem
        super().__init__(f"cannot export: {field}={value!r}: {problem}")
