"""`torchrun` for the torch this project runs on: `python -m plasticitynet.training.torchrun ARGS` is
`torchrun ARGS` (same options, single- and multi-machine rendezvous).

Debian's torch 1.13 `torchrun` fails at start under Python >= 3.11 ("'NoneType' object has no attribute
'get'"): its `Std.from_str` looks the stream number up by iterating the IntFlag `Std`, and since Python
3.11 that iteration skips the zero and multi-bit members (NONE, ALL), so the default "0" becomes None.
Where that is the case this module replaces the lookup with `Std(int(v))`; torch >= 2 fixed it upstream
and runs unchanged.
"""

from __future__ import annotations

import re
import sys


def _patch_std_from_str() -> None:
    from torch.distributed.elastic.multiprocessing import api

    Std = api.Std
    try:
        broken = Std.from_str("0") is None
    except Exception:
        broken = False
    if not broken:
        return

    def from_str(vm: str):
        if re.match(api._VALUE_REGEX, vm):
            return Std(int(vm))
        if re.match(api._MAPPING_REGEX, vm):
            return {int(i): Std(int(v)) for i, v in (m.split(":") for m in vm.split(","))}
        raise ValueError(f"{vm} does not match: <{api._VALUE_REGEX}> or <{api._MAPPING_REGEX}>")

    Std.from_str = staticmethod(from_str)


def main(argv=None) -> int:
    _patch_std_from_str()
    from torch.distributed.run import main as torchrun_main

    torchrun_main(argv if argv is not None else sys.argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
