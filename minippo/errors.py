"""The errors minippo reports to a user in one line (the command line prints them without a traceback)."""


class MinippoError(Exception):
    """Something the user can fix: bad input, a missing file, an unsupported environment."""


class ConfigError(MinippoError):
    """A Config field with a value it cannot take; ``field`` names it (the command line names its option instead)."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


class NonFiniteError(MinippoError):
    """A NaN or an infinity appeared in observations, rewards, losses or gradients."""
