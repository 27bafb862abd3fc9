"""The one field table of ``gl_gains_t`` (gainlink.shipping.gains_layout): the C compilers (host and Cortex-M4F) lay the
struct out as the table's ctypes mirror and packer say, for today's table and for one extended as the scheduled
and fixed-point laws will extend it (int32/int16/int8 elements, an extra extent, a format signature)."""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping import gains_layout as gl
from gainlink.shipping.codegen import gain_set, render_c, shape_of

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
STRICT = ["-std=c11", "-Wall", "-Wextra", "-Werror", "-pedantic"]
CORTEX_M4F = ["-mcpu=cortex-m4", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-mthumb"]


def compile_c(compiler: str, flags: list[str], sources: list[Path], includes: list[Path], out: Path | None):
    cmd = [compiler, *STRICT, *flags, *(f"-I{p}" for p in includes)]
    cmd += ["-o", str(out), *map(str, sources)] if out else ["-fsyntax-only", *map(str, sources)]
    return subprocess.run(cmd, capture_output=True, text=True)


def c_view_program(layout: gl.Layout, fill: bool) -> str:
    """C that prints offsetof/sizeof of every field, then (``fill``) the bytes of a struct whose every element k
    of the i-th field holds (10 i + k) % 100, memset to zero first so padding is zero."""
    t = f"{layout.struct}_t"
    lines = ["#include <stdio.h>", "#include <string.h>", "int main(void)", "{", f"    static {t} s;"]
    lines += [f'    printf("{f.name} %zu %zu\\n", offsetof({t}, {f.name}), sizeof s.{f.name});' for f in layout.fields]
    if fill:
        lines.append("    memset(&s, 0, sizeof s);")
        for i, f in enumerate(layout.fields):
            lines.append(
                f"    {{ {f.type.c} *e = ({f.type.c} *)&s.{f.name};"
                f" for (size_t k = 0; k < sizeof s.{f.name} / sizeof *e; ++k)"
                f" e[k] = ({f.type.c})(({10 * i}u + k) % 100u); }}"
            )
        lines.append('    for (size_t b = 0; b < sizeof s; ++b) printf("%02x", ((unsigned char *)&s)[b]);')
        lines.append('    printf("\\n");')
    return "\n".join([*lines, "    return 0;", "}", ""])


def filled_values(layout: gl.Layout, shape) -> dict[str, np.ndarray]:
    """What :func:`c_view_program` writes into each field."""
    out = {}
    for i, f in enumerate(layout.fields):
        dims = f.shape(shape)
        out[f.name] = ((10 * i + np.arange(int(np.prod(dims, dtype=int)))) % 100).astype(f.type.dtype).reshape(dims)
    return out


def run_c_view(tmp: Path, header_dir: Path, program: str, extra: list[Path] = (), includes=()) -> list[str]:
    main = tmp / "view.c"
    main.write_text(program)
    exe = tmp / "view"
    proc = compile_c("cc", [], [main, *extra], [header_dir, *includes], exe)
    assert proc.returncode == 0, proc.stderr
    return subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.splitlines()


def parse_offsets(lines: list[str]) -> dict[str, tuple[int, int]]:
    rows = [ln.split() for ln in lines if len(ln.split()) == 3]
    return {name: (int(off), int(size)) for name, off, size in rows}


@pytest.mark.parametrize("name", ["pendulum", "quadrotor_lateral", "wood_berry"])
def test_the_compilers_lay_out_gl_gains_t_as_the_table_says(example_artifacts, tmp_path, name):
    """Host: offsets, sizes and the bytes of the compiled ``gl_gains_default`` equal the table's mirror and packer;
    Cortex-M4F: the generated header's layout assertions hold under arm-none-eabi-gcc."""
    art = artifact_mod.load(example_artifacts[name])
    gen = tmp_path / "gen"
    gen.mkdir()
    for fname, text in render_c(art).items():
        (gen / fname).write_text(text)
    shape = shape_of(art)
    program = '#include "gainlink/gl_loop.h"\n' + c_view_program(gl.GAINS, fill=False).replace(
        "    return 0;",
        '    for (size_t b = 0; b < sizeof gl_gains_default; ++b) printf("%02x", '
        "((const unsigned char *)&gl_gains_default)[b]);\n    return 0;",
    )
    lines = run_c_view(tmp_path, gen, program, [gen / "gl_gains.c"], [FIRMWARE / "include"])
    assert parse_offsets(lines) == gl.GAINS.offsets(shape)
    assert bytes.fromhex(lines[-1]) == gl.GAINS.pack(shape, gain_set(art).fields)
    tu = tmp_path / "m4.c"
    tu.write_text('#include "gainlink/gl_loop.h"\n')
    proc = compile_c("arm-none-eabi-gcc", CORTEX_M4F, [tu], [FIRMWARE / "include", gen], None)
    assert proc.returncode == 0, proc.stderr


@dataclass(frozen=True)
class ScheduledFixedShape:
    """The structure of the extended table: today's plus schedule points and a format signature."""

    n: int
    m: int
    p: int
    q: int
    observer_form: int
    anti_windup: int
    points: int
    formats: int


def extended_layout() -> gl.Layout:
    """A table as the next laws will write it: per-point coefficients over an extra extent, sigma settings,
    integer coefficients with per-variable shift counts, and a signature of the number formats."""
    structure = [f for f in gl.FIELDS if f.role == "structure"]
    return gl.Layout(
        "gl_ext_gains",
        (
            *structure,
            gl.Field("points", "uint32_t", (), "structure", "Schedule points.", param="GL_PTS", compiled="GL_PTS"),
            gl.Field("formats", "uint32_t", (), "structure", "Formats.", param="GL_FMT", compiled="GL_FORMATS"),
            gl.Field("Ts", "float", (), "number", "Sample time.", param="TS"),
            gl.Field("sigma", "float", ("GL_PTS",), "number", "Schedule points.", param="SIG"),
            gl.Field("sigma_rate", "float", (), "number", "Rate limit.", param="SIGR"),
            gl.Field("Kx", "float", ("GL_PTS", "GL_M", "GL_N"), "number", "Per-point gains."),
            gl.Field("Kq", "int32_t", ("GL_M", "GL_N"), "number", "q31 gain.", param="KQ"),
            gl.Field("Kq15", "int16_t", ("GL_M", "GL_QA"), "number", "q15 gain.", param="KQS"),
            gl.Field("shift", "int8_t", ("GL_N",), "number", "Shift counts.", param="SH"),
            gl.Field("y15", "int16_t", ("GL_P",), "number", "q15 offsets.", param="YQ"),
            gl.Field("crc32", "uint32_t", (), "checksum", "CRC-32."),
        ),
        "@brief A gain set of a scheduled, fixed-point law (test only).",
    )


@pytest.mark.parametrize(
    "dims", [dict(n=3, m=2, p=1, q=0, points=3), dict(n=5, m=1, p=3, q=2, points=2), dict(n=1, m=1, p=1, q=1, points=4)]
)
def test_an_extended_table_with_integer_elements_and_an_extra_extent(monkeypatch, tmp_path, dims):
    """Element types of 4, 2 and 1 bytes after the floats (so the compiler pads before crc32) and a three-index
    field: the compilers, the ctypes mirror and the packer agree on every offset and every byte."""
    monkeypatch.setitem(gl.DIMENSIONS, "GL_PTS", gl.Dimension(lambda s: s.points, "GL_PTS", lambda s: s.points))
    layout = extended_layout()
    shape = ScheduledFixedShape(observer_form=0, anti_windup=0, formats=0x0F31, **dims)
    macros = "".join(
        f"#define {k} {v}\n"
        for k, v in {
            "GL_N": shape.n,
            "GL_M": shape.m,
            "GL_P": shape.p,
            "GL_Q": shape.q,
            "GL_QA": max(shape.q, 1),
            "GL_PTS": shape.points,
            "GL_FORMATS": shape.formats,
            "GL_OBSERVER_FORM": 0,
            "GL_ANTI_WINDUP": 0,
            "GL_FORM_CURRENT": 1,
        }.items()
    )
    (tmp_path / "gl_ext_gains_layout.h").write_text(
        macros + layout.render_header(banner="/* DO NOT EDIT — test */\n", shape=shape)
    )
    program = '#include "gl_ext_gains_layout.h"\n' + c_view_program(layout, fill=True)
    lines = run_c_view(tmp_path, tmp_path, program)
    offsets = layout.offsets(shape)
    assert parse_offsets(lines) == offsets
    padding = len(layout.pack(shape, {})) - sum(size for _, size in offsets.values())
    assert padding > 0  # the case a hand-computed packing gets wrong
    assert bytes.fromhex(lines[-1]) == layout.pack(shape, filled_values(layout, shape))
    tu = tmp_path / "m4.c"
    tu.write_text('#include "gl_ext_gains_layout.h"\n')
    proc = compile_c("arm-none-eabi-gcc", CORTEX_M4F, [tu], [tmp_path], None)
    assert proc.returncode == 0, proc.stderr
    header = (tmp_path / "gl_ext_gains_layout.h").read_text()
    assert 'X(formats, GL_FORMATS, "GL_FMT")' in header and "X(Kx," not in header  # three indices: no param ids
    assert "#define GL_EXT_GAINS_FLOATS \\\n    (1 + GL_PTS + 1 + GL_PTS * GL_M * GL_N)" in header


def test_a_layout_the_compiler_disagrees_with_does_not_build(example_artifacts, tmp_path):
    """The layout assertions bite: a mirror one float off (as a hand-edited copy would be) stops the build."""
    art = artifact_mod.load(example_artifacts["pendulum"])
    files = render_c(art)
    header = files[gl.HEADER_NAME]
    k_offset = gl.GAINS.offsets(shape_of(art))["K"][0]
    tampered, count = re.subn(
        rf"offsetof\(gl_gains_t, K\) == {k_offset}u", f"offsetof(gl_gains_t, K) == {k_offset + 4}u", header
    )
    assert count == 1
    files[gl.HEADER_NAME] = tampered
    for fname, text in files.items():
        (tmp_path / fname).write_text(text)
    tu = tmp_path / "t.c"
    tu.write_text('#include "gainlink/gl_loop.h"\n')
    proc = compile_c("cc", [], [tu], [FIRMWARE / "include", tmp_path], None)
    assert proc.returncode != 0 and "gl_gains_t.K: layout differs from gainlink.shipping.gains_layout" in proc.stderr


def test_the_table_refuses_an_order_the_c_cannot_use():
    """Structure fields first, floats contiguous, one checksum last: the C's CRC and checks rely on it."""
    fields = list(gl.FIELDS)
    with pytest.raises(ValueError, match="structure fields, the numbers, then the checksum"):
        gl.Layout("gl_bad", (fields[6], *fields[:6], *fields[7:]), "")
    gap = gl.Field("shift", "int8_t", ("GL_N",), "number", "Shift counts.")
    with pytest.raises(ValueError, match="float numbers of gl_bad_t must be contiguous"):
        gl.Layout("gl_bad", (*fields[:7], gap, *fields[7:]), "")
    with pytest.raises(ValueError, match="unknown element type or dimension"):
        gl.Layout("gl_bad", (*fields[:-1], gl.Field("x", "float", ("GL_NOPE",), "number", ""), fields[-1]), "")
