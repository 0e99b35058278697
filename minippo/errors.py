"""The errors minippo reports to a user in one line (the command line prints them without a traceback)."""


class MinippoError(Exception):
    """Something the user can fix: bad input, a missing file, an unsupported environment."""


class NonFiniteError(MinippoError):
    """A NaN or an infinity appeared in observations, rewards, losses or gradients."""
