"""Error types shared by the cores, at the bottom of the layers so no core imports another for them."""


class InvalidInputError(ValueError):
    """Images or camera parameters that cannot be turned into a grasp."""
