from os import PathLike
from typing import Any, Union

from mavstack._native import Key, mavlogfile

def mavlink_connection(
    device: Union[str, PathLike], dialect: str = "ardupilotmega", key: Key = None, **kwargs: Any
) -> mavlogfile: ...
