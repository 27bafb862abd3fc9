"""Flash/RAM size report of a Cortex-M image, per section, from ``arm-none-eabi-objdump -h``."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from ..errors import ToolchainError

RAM_BASE = 0x20000000
_SECTION = re.compile(r"^\s*\d+\s+(\S+)\s+([0-9a-f]+)\s+([0-9a-f]+)\s+([0-9a-f]+)\s+[0-9a-f]+\s+\S+\s*$")


def tool(name: str) -> str:
    """Path of the binutils program ``name`` (arm-none-eabi-*)."""
    path = shutil.which(name)
    if path is None:
        raise ToolchainError(f"{name} not found: install binutils-arm-none-eabi (make setup)")
    return path


def symbol_sizes(elf: Path, names: tuple[str, ...]) -> dict[str, dict]:
    """Address and size of the named symbols (``arm-none-eabi-nm -S``); absent names are left out."""
    out = subprocess.run([tool("arm-none-eabi-nm"), "-S", str(elf)], capture_output=True, text=True, check=True)
    found = {}
    for line in out.stdout.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[3] in names:
            found[parts[3]] = {"address": int(parts[0], 16) & ~1, "size": int(parts[1], 16)}
    return found


def size_report(elf: Path, *, board: str) -> dict:
    """Sections with their flash and RAM use, totals, and the loop's main symbols.

    A section counts towards flash when its contents are loaded into the image (code, constants,
    the initial values of ``.data``), towards RAM when it lives at or above 0x20000000 (``.data``,
    ``.bss``, the stack). ``flash_bytes`` is the span those sections take in flash, from the first's start to the
    last's end, with the alignment gaps between them (what the ``.bin`` holds and a probe writes).
    """
    out = subprocess.run([tool("arm-none-eabi-objdump"), "-h", str(elf)], capture_output=True, text=True, check=True)
    lines = out.stdout.splitlines()
    sections = []
    for i, line in enumerate(lines):
        m = _SECTION.match(line)
        if not m:
            continue
        flags = lines[i + 1].strip() if i + 1 < len(lines) else ""
        if "ALLOC" not in flags:
            continue
        name, size, vma, lma = m.group(1), int(m.group(2), 16), int(m.group(3), 16), int(m.group(4), 16)
        in_flash = "LOAD" in flags and lma < RAM_BASE
        in_ram = vma >= RAM_BASE
        sections.append({"name": name, "size": size, "vma": vma, "lma": lma, "flash": in_flash, "ram": in_ram})
    symbols = symbol_sizes(elf, ("gl_loop_step", "gl_gains_default", "loop", "gl_coeffs_derive"))
    return {
        "board": board,
        "elf": elf.name,
        "sections": sections,
        "flash_bytes": _flash_span(sections),
        "ram_bytes": sum(s["size"] for s in sections if s["ram"]),
        "ram_bytes_without_stack": sum(s["size"] for s in sections if s["ram"] and s["name"] != ".stack"),
        "symbols": symbols,
    }


def _flash_span(sections: list[dict]) -> int:
    loaded = [(s["lma"], s["lma"] + s["size"]) for s in sections if s["flash"] and s["size"] > 0]
    return max(end for _, end in loaded) - min(start for start, _ in loaded) if loaded else 0
