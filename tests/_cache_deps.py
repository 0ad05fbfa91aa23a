"""What each module declares to ``wpt_receiver.kernel_cache.drop_stale_cache`` at its import, read in a fresh process."""

import json
import subprocess
import sys


def declared_cache_deps(module: str) -> dict:
    """``{file name of the module calling drop_stale_cache: [file names it names]}`` recorded while ``import module``
    runs in a fresh interpreter (``kernel_cache.drop_stale_cache`` swapped for a recorder first)."""
    code = ("import json, os\n"
            "import wpt_receiver.kernel_cache as kc\n"
            "seen = {}\n"
            "def record(here, modules):\n"
            "    seen[os.path.basename(here.__code__.co_filename)] = [os.path.basename(str(getattr(m, '__file__', m)))"
            " for m in modules]\n"
            "    return False\n"
            "kc.drop_stale_cache = record\n"
            f"import {module}\n"
            "print(json.dumps(seen))\n")
    return json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
