"""A small Linux VM with a real ``vcan0``: real SocketCAN on machines whose kernel has no CAN.

The VM is qemu-system-x86_64 (TCG) booting Debian's own 6.1 kernel (``apt-get download``, unpacked
into an ignored cache folder; the uncompressed ``vmlinux`` is cut out of the bzImage and booted
through PVH), with a busybox-static initramfs that loads the CAN, virtio and 9p modules, mounts the
host ``/`` read-only over 9p (``multidevs=remap``) under a tmpfs overlay, brings up ``vcan0`` (MTU 72
for CAN FD) and runs one shell script in a chroot of that overlay. A second, writable 9p share is the
script's folder, so its results land on the host. The exit status is printed on the serial console.
"""

from __future__ import annotations

import compileall
import glob
import hashlib
import io
import logging
import lzma
import os
import re
import shutil
import subprocess
import tarfile
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import gainlink.errors
from gainlink.errors import ToolchainError
from gainlink.fileio import exclusive_lock

from ..paths import cache_dir

log = logging.getLogger(__name__)

MODULES = ("can", "can_raw", "can_dev", "vcan", "virtio_pci", "9pnet_virtio", "9p", "overlay")
STATUS_MARK = "GAINLINK_VM_STATUS="

INIT = r"""#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/bin
mkdir -p /proc /sys /dev /host /ovl /newroot
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in $(cat /modules.order); do insmod /lib/modules/$m || echo "gainlink-vm: insmod $m failed"; done
OUT=$(sed -n 's/.*gl_out=\([^ ]*\).*/\1/p' /proc/cmdline)
mount -t 9p -o trans=virtio,version=9p2000.L,ro,msize=512000,cache=loose hostroot /host \
  || echo "gainlink-vm: 9p mount failed"
mount -t tmpfs -o size=256m tmpfs /ovl
mkdir -p /ovl/upper /ovl/work
mount -t overlay overlay -o lowerdir=/host,upperdir=/ovl/upper,workdir=/ovl/work /newroot \
  || echo "gainlink-vm: overlay failed"
mount -t proc proc /newroot/proc
mount -t sysfs sys /newroot/sys
mount -t devtmpfs dev /newroot/dev
mount -t tmpfs tmpfs /newroot/run
mkdir -p "/newroot$OUT"
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 hostout "/newroot$OUT" || echo "gainlink-vm: out mount failed"
ip link set lo up
ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 && ip link set up vcan0 || echo "gainlink-vm: vcan0 failed"
chroot /newroot /usr/bin/env -i PATH=/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin HOME=/root LANG=C.UTF-8 \
    MPLBACKEND=Agg /bin/sh -c "cd '$OUT' && exec /bin/sh ./run.sh"
echo "GAINLINK_VM_STATUS=$?"
sync
poweroff -f
"""


@dataclass(frozen=True)
class VmImage:
    """The files the VM boots from."""

    kernel: Path
    initrd: Path
    version: str


@dataclass(frozen=True)
class VmRun:
    """The outcome of one VM run: the script's exit status (None if none was printed), console text, seconds."""

    status: int | None
    console: str
    seconds: float


def _download_kernel_deb(dest: Path) -> Path:
    debs = sorted(dest.glob("linux-image-6.1.*-amd64_*.deb"))
    if debs:
        return debs[-1]
    if shutil.which("apt-get") is None or shutil.which("apt-cache") is None:
        raise ToolchainError("the vcan VM needs apt-get to download Debian's kernel package")

    def lookup() -> re.Match | None:
        deps = subprocess.run(["apt-cache", "depends", "linux-image-amd64"], capture_output=True, text=True)
        return re.search(r"Depends:\s*(linux-image-6\.1\.\S+-amd64)\b", deps.stdout)

    m = lookup()
    if m is None:  # empty package lists on a fresh machine: refresh them once
        subprocess.run(["apt-get", "update", "-qq"], capture_output=True, text=True)
        m = lookup()
    if m is None:
        raise ToolchainError("apt-cache knows no linux-image-6.1.*-amd64 package (run apt-get update)")
    log.info("downloading %s for the vcan VM", m.group(1))
    with tempfile.TemporaryDirectory(dir=dest) as tmp:  # the .deb appears under its name only when complete
        proc = subprocess.run(["apt-get", "download", m.group(1)], cwd=tmp, capture_output=True, text=True)
        debs = sorted(Path(tmp).glob("linux-image-6.1.*-amd64_*.deb"))
        if proc.returncode != 0 or not debs:
            raise ToolchainError(f"apt-get download {m.group(1)} failed: {proc.stderr.strip()[-300:]}")
        os.replace(debs[-1], dest / debs[-1].name)
    return dest / debs[-1].name


def _extract(deb: Path, into: Path) -> None:
    """Unpack only the kernel image and the module folders the VM needs (``dpkg-deb --fsys-tarfile``)."""
    tar_bytes = subprocess.run(["dpkg-deb", "--fsys-tarfile", str(deb)], capture_output=True, check=True).stdout
    wanted = re.compile(
        r"^\./(boot/vmlinuz-|lib/modules/[^/]+/kernel/(net/can|net/9p|fs/9p|fs/netfs|fs/fscache|"
        r"fs/overlayfs|drivers/virtio|drivers/net/can))"
    )
    with tarfile.open(fileobj=io.BytesIO(tar_bytes)) as tf:
        members = [m for m in tf.getmembers() if (m.isfile() or m.isdir()) and wanted.match(m.name)]
        tf.extractall(into, members=members, filter="data")


def _vmlinux(vmlinuz: Path, out: Path) -> None:
    """Cut the XZ payload out of a bzImage and decompress it to the ELF vmlinux (bootable via PVH)."""
    data = vmlinuz.read_bytes()
    for m in re.finditer(re.escape(b"\xfd7zXZ\x00"), data):
        dec = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)
        try:
            elf = dec.decompress(data[m.start() :])
        except lzma.LZMAError:
            continue
        if elf[:4] == b"\x7fELF":
            out.write_bytes(elf)
            return
    raise ToolchainError(f"no XZ-compressed ELF kernel found in {vmlinuz}")


def _module_closure(root: Path) -> list[Path]:
    """The needed modules and their dependencies (read from each .ko's modinfo), dependencies first."""
    files = {p.stem.replace("-", "_"): p for p in root.rglob("*.ko")}
    order: list[Path] = []
    seen: set[str] = set()

    def visit(name: str) -> None:
        name = name.replace("-", "_")
        if name in seen:
            return
        seen.add(name)
        path = files.get(name)
        if path is None:
            raise ToolchainError(f"kernel module {name} not found in the kernel package")
        m = re.search(rb"depends=([^\x00]*)", path.read_bytes())
        for dep in m.group(1).decode().split(",") if m and m.group(1) else []:
            visit(dep)
        order.append(path)

    for name in MODULES:
        visit(name)
    return order


def _cpio_newc(entries: list[tuple[str, int, bytes]]) -> bytes:
    """A newc cpio archive of (path, mode, content) entries (directories have empty content)."""
    out = io.BytesIO()
    ino = 1
    for name, mode, data in entries + [("TRAILER!!!", 0, b"")]:
        nb = name.encode() + b"\0"
        hdr = "070701" + "".join(f"{v:08x}" for v in (ino, mode, 0, 0, 1, 0, len(data), 0, 0, 0, 0, len(nb), 0))
        out.write(hdr.encode() + nb)
        out.write(b"\0" * ((4 - (110 + len(nb)) % 4) % 4))
        out.write(data)
        out.write(b"\0" * ((4 - len(data) % 4) % 4))
        ino += 1
    return out.getvalue()


def prepare_vm(*, cache: Path | None = None) -> VmImage:
    """Download, unpack and assemble the VM (cached; a few seconds the first time)."""
    busybox = Path("/bin/busybox")
    if not busybox.is_file():
        raise ToolchainError("the vcan VM needs busybox-static (/bin/busybox)")
    if shutil.which("qemu-system-x86_64") is None:
        raise ToolchainError("the vcan VM needs qemu-system-x86 (qemu-system-x86_64)")
    root = cache or cache_dir("vcan-vm")
    with exclusive_lock(root / ".lock"):  # one process downloads and assembles; the others wait and reuse it
        return _assemble(root, busybox)


def _assemble(root: Path, busybox: Path) -> VmImage:
    """The VM's kernel and initramfs in ``root`` (downloaded and built there unless already done)."""
    deb = _download_kernel_deb(root)
    version = re.sub(r"_amd64\.deb$", "", deb.name)
    recipe = hashlib.sha256((INIT + "|".join(MODULES)).encode()).hexdigest()[:12]
    work = root / f"{version}-{recipe}"
    kernel, initrd = work / "vmlinux", work / "initramfs.cpio"
    if kernel.is_file() and initrd.is_file():
        return VmImage(kernel=kernel, initrd=initrd, version=version)
    with tempfile.TemporaryDirectory(dir=root) as tmp:
        tmp = Path(tmp)
        _extract(deb, tmp)
        vmlinuz = next(iter(glob.glob(str(tmp / "boot" / "vmlinuz-*"))), None)
        if vmlinuz is None:
            raise ToolchainError(f"{deb.name} holds no boot/vmlinuz")
        staged = tmp / "out"
        staged.mkdir()
        _vmlinux(Path(vmlinuz), staged / "vmlinux")
        mods = _module_closure(tmp / "lib" / "modules")
        entries: list[tuple[str, int, bytes]] = [(d, 0o40755, b"") for d in ("bin", "lib", "lib/modules")]
        entries.append(("bin/busybox", 0o100755, busybox.read_bytes()))
        entries.append(("init", 0o100755, INIT.encode()))
        entries.append(("modules.order", 0o100644, "".join(f"{p.name}\n" for p in mods).encode()))
        entries += [(f"lib/modules/{p.name}", 0o100644, p.read_bytes()) for p in mods]
        (staged / "initramfs.cpio").write_bytes(_cpio_newc(entries))
        work.mkdir(parents=True, exist_ok=True)
        for name in ("vmlinux", "initramfs.cpio"):
            os.replace(staged / name, work / name)
    return VmImage(kernel=kernel, initrd=initrd, version=version)


def _compile_gainlink() -> None:
    """Write the bytecode of gainlink's modules on the host (a no-op when current): the VM sees the host root
    read-only, so Python there cannot cache it and would compile every module again under emulation (5-10 s)."""
    for package in (Path(gainlink.errors.__file__).parent, Path(__file__).resolve().parents[1]):
        compileall.compile_dir(package, quiet=1)


def run_in_vm(
    script: str, *, workdir: Path, timeout: float = 600.0, memory_mb: int = 768, image: VmImage | None = None
) -> VmRun:
    """Boot the VM, run ``script`` (sh) in a chroot of the host root with ``vcan0`` up, and power off.

    ``workdir`` (a host folder) is shared writable at the same path inside the VM and is the
    script's working directory; the script is written there as ``run.sh``. The VM is always killed
    after ``timeout`` seconds.
    """
    image = image or prepare_vm()
    _compile_gainlink()
    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "run.sh").write_text(script, "utf-8")
    # TCG even where /dev/kvm opens: a sandbox's KVM may be PVM (kvm_pvm: nested, without hardware virtualisation),
    # on which Debian's kernel never boots (no console output at all; with -cpu max QEMU aborts setting MSR 0x10a).
    cmd = [
        "qemu-system-x86_64",
        "-accel",
        "tcg",
        "-cpu",
        "max",
        "-m",
        str(memory_mb),
        "-smp",
        "1",
        "-nodefaults",
        "-display",
        "none",
        "-serial",
        "stdio",
        "-monitor",
        "none",
        "-no-reboot",
        "-kernel",
        str(image.kernel),
        "-initrd",
        str(image.initrd),
        "-append",
        f"console=ttyS0 panic=-1 quiet loglevel=3 gl_out={workdir}",
        "-virtfs",
        "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap",
        "-virtfs",
        f"local,path={workdir},mount_tag=hostout,security_model=none,multidevs=remap",
    ]
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    console = out.decode(errors="replace")
    m = re.search(STATUS_MARK + r"(\d+)", console)
    return VmRun(status=int(m.group(1)) if m else None, console=console, seconds=time.monotonic() - t0)
