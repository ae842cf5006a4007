"""Result codes and how every failure becomes a coded reply.

Replies are (success, "CODE: message"). A handler raises RequestError with the code it means;
errors from validation carry their code in their type (specs.InvalidName: NAME_INVALID), never
in their text.
"""
import functools

from ..frame_names import FrameTaken
from ..physics import specs
from ..scene import MissingMesh, UnsupportedMesh

OK = "RESULT_OK"
NOT_FOUND = "RESULT_NOT_FOUND"
INCORRECT_STATE = "RESULT_INCORRECT_STATE"
FAILED = "RESULT_OPERATION_FAILED"
NAME_NOT_UNIQUE = "NAME_NOT_UNIQUE"
NAME_INVALID = "NAME_INVALID"
INVALID_POSE = "INVALID_POSE"
ALREADY = "ALREADY_IN_TARGET_STATE"
INCORRECT_TRANSITION = "INCORRECT_TRANSITION"
NO_RESOURCE = "NO_RESOURCE"
UNSUPPORTED_FORMAT = "UNSUPPORTED_FORMAT"
RESOURCE_PARSE_ERROR = "RESOURCE_PARSE_ERROR"
FEATURE_UNSUPPORTED = "RESULT_FEATURE_UNSUPPORTED"
NO_WORLD_LOADED = "NO_WORLD_LOADED"
MISSING_ASSETS = "MISSING_ASSETS"
UNSUPPORTED_ASSETS = "UNSUPPORTED_ASSETS"

# nav_msgs/srv/LoadMap result codes.
MAP_SUCCESS, MAP_DOES_NOT_EXIST, INVALID_MAP_DATA, UNDEFINED_FAILURE = 0, 1, 2, 255


class RequestError(Exception):
    def __init__(self, code, message):
        super().__init__(f"{code}: {message}")
        self.code = code


def reply(code, message):
    return code == OK, f"{code}: {message}"


def handled(fn):
    """Turns every refusal into a coded reply. What no request should cause (a bug) is left to
    the caller: the service table answers it as an internal error, logged and counted
    (services.guarded)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except RequestError as error:
            return False, str(error)
        except specs.SpecError as error:
            return False, f"{spec_error_code(error)}: {error}"
        except KeyError as error:
            return False, f"{NOT_FOUND}: {error.args[0] if error.args else 'no such entity'}"
        except TimeoutError as error:
            return False, f"{FAILED}: {error}"
        except ValueError as error:
            return False, f"{FAILED}: {str(error)[:500]}"
    return wrapper


def spec_error_code(error):
    """The code of a refused value, by its type: a bad name, a name that is another entity's
    frame, a mesh file missing or of a type no reader takes, else FAILED."""
    if isinstance(error, specs.InvalidName):
        return NAME_INVALID
    if isinstance(error, FrameTaken):
        return NAME_NOT_UNIQUE
    if isinstance(error, MissingMesh):
        return MISSING_ASSETS
    if isinstance(error, UnsupportedMesh):
        return UNSUPPORTED_ASSETS
    return FAILED


def internal_error(error):
    """The reply text of an exception no request should cause."""
    return f"{FAILED}: internal error ({type(error).__name__}: {str(error)[:300]})"

