"""`Phidget22.PhidgetException` stand-in."""


class PhidgetException(Exception):
    def __init__(self, code: int, details: str = "") -> None:
        super().__init__(f"{code}: {details}")
        self.code = code
        self.details = details
