"""Where the GPU kernels run: a CUDA device through CuPy, or the host CPU (emulation).

Both compile ``kernel.cu`` for a number of arms K (``-DKARMS=K``) and call its entry points
``advance_<family>_<c><a>`` (``c``: the correlated form, ``a``: the AoI-aware form) with the
same arguments (:data:`corraoi.gpu.runner` builds them):

* :class:`CudaDevice` -- CuPy's NVRTC compiles the source once per K and family (one family's
  entry points a module, ``-DCAI_FAMILY``); CuPy caches the binary on disk
  (``$CUPY_CACHE_DIR``, by default ``~/.cupy/kernel_cache``), so a new process only loads it.
  One CUDA thread per run, 128 threads a block. Launches are queued on CuPy's current stream
  and return at once; :meth:`Device.mark` and :meth:`Device.wait` follow them.
* :class:`EmulatedDevice` -- the same source compiled by the host C++ compiler (``$CXX``, else
  g++ or c++) into a shared library in corraoi's cache folder, its runs spread over the cores
  with OpenMP. It runs the GPU code where no GPU is (tests, development); it is not fast.
  ``CORRAOI_GPU_DEVICE=emulate`` makes ``--backend gpu`` use it.

A captured run (``record --from``, :func:`corraoi.gpu.runner.capture_run`) launches a module
of its own, compiled with ``-DCAI_CAPTURE=1`` (``capture=True``): it also captures why each
arm was played (score, forced, the override's threshold). A sweep's modules are compiled
without it, from the same preprocessed text as before that capture existed.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from corraoi.errors import GpuUnavailable

SOURCE_PATH = Path(__file__).with_name("kernel.cu")
#: The policy families of kernel.cu, in its order (CAI_FAMILY is the place here, from 1).
FAMILIES = ("ucb", "ts_beta", "ts_gauss", "q_ucb", "q_ts", "sw_ucb", "d_ts")
#: Families without a correlated form: kernel.cu has their plain and AoI-aware entries only.
UNCORRELATED = ("sw_ucb", "d_ts")
#: Per-run arrays live in registers up to about this many arms; beyond, use the CPU engine.
MAX_ARMS = 64
#: The environment variable that picks the emulated device for ``--backend gpu``.
DEVICE_ENV = "CORRAOI_GPU_DEVICE"
#: How the checkpoints' per-run values become moments over the runs (Device.reduction):
#: "kernel", kernel.cu's reduce_checkpoints (one pass, exact integer sums); "arrays", the
#: array module's reductions (Moments.of on CuPy or NumPy arrays: the path of the second GPU
#: run, kept to be timed and checked beside the first, and to fall back on).
REDUCTIONS = ("kernel", "arrays")

#: Argument kinds of an entry point: int32, int64, uint64, float64, array.
ArgList = Sequence[tuple[str, Any]]


def source() -> str:
    return SOURCE_PATH.read_text(encoding="utf-8")


def family_id(family: str) -> int:
    """kernel.cu's CAI_FAMILY for ``family``: its place in FAMILIES, from 1."""
    return FAMILIES.index(family) + 1


def entry_name(family: str, correlated: bool, aware: bool) -> str:
    """kernel.cu's entry point for a family's form: ``advance_<family>_<c><a>``."""
    return f"advance_{family}_{int(bool(correlated))}{int(bool(aware))}"


def entry_names(family: str | None = None) -> list[str]:
    """Every entry point kernel.cu defines (of ``family``, or of all), philox_kat aside."""
    return [entry_name(f, c, a) for f in (FAMILIES if family is None else (family,))
            for c in ((False,) if f in UNCORRELATED else (False, True))
            for a in (False, True)]  # fmt: skip


class Device(ABC):
    """A place to run kernel.cu: arrays of its module ``xp`` (NumPy or CuPy) and launches."""

    #: In words, for notices and benchmark tables.
    name: str = ""
    #: NumPy or CuPy: the array module of this device's arrays (reductions run on it).
    xp: Any = np
    #: Run-slots per launch: bounds each call, so that progress moves and Ctrl-C is heard.
    launch_work: int = 1 << 24
    #: Slots per launch at most, whatever the runs (the launch's table of ln t has one each).
    launch_slots: int = 1 << 20
    #: Launches queued beyond the one the host waits for (0: each call returns when done).
    in_flight: int = 0
    #: Bytes for the per-run values captured at checkpoints between two reductions.
    checkpoint_bytes: int = 256 << 20
    #: Seconds spent compiling (or loading) modules in this process.
    compile_seconds: float = 0.0
    #: One of REDUCTIONS: how a launch's checkpoint values are reduced over the runs.
    reduction: str = "kernel"

    def __init__(self, *, reduction: str | None = None) -> None:
        self._compiled: dict[int, Any] = {}
        self._lock = threading.Lock()
        if reduction is not None:
            if reduction not in REDUCTIONS:
                raise ValueError(f"reduction {reduction!r}: expected one of "
                                 f"{', '.join(REDUCTIONS)}")  # fmt: skip
            self.reduction = reduction

    @abstractmethod
    def _compile(self, K: int, family: str, capture: bool = False) -> Any:
        """Build (or load from a cache) kernel.cu for K arms with (at least) ``family``'s entry
        points: a CuPy module or a library (``capture``: the capture module, CAI_CAPTURE=1)."""

    def _module_key(self, K: int, family: str, capture: bool = False) -> Any:
        return (K, family, capture)

    def module(self, K: int, family: str, capture: bool = False) -> Any:
        """The K-arm module of ``family`` (``capture``: the one that captures a run's scores),
        compiled once per process (the time goes to compile_seconds)."""
        key = self._module_key(K, family, capture)
        with self._lock:
            mod = self._compiled.get(key)
            if mod is None:
                start = time.perf_counter()
                mod = self._compile(K, family, capture)
                self.compile_seconds += time.perf_counter() - start
                self._compiled[key] = mod
            return mod

    @abstractmethod
    def launch(self, K: int, family: str, entry: str, runs: int, args: ArgList, *,
               capture: bool = False) -> None:  # fmt: skip
        """Run ``entry`` (``advance_<family>_<c><a>``) of the K-arm module of ``family`` (its
        capture module with ``capture``) over ``runs`` runs."""

    @abstractmethod
    def reduce(self, K: int, family: str, nck: int, runs: int, args: ArgList) -> None:
        """Run ``reduce_checkpoints`` of the K-arm module of ``family`` over ``nck``
        checkpoints of ``runs`` runs (``args``: corraoi.gpu.checkpoints.reduce_checkpoints)."""

    def mark(self) -> Any:
        """A mark after the launches queued so far (None where calls return when done)."""
        return None

    def wait(self, mark: Any) -> None:  # noqa: B027 (a no-op where calls return when done)
        """Wait until the launches before ``mark`` are done."""

    @abstractmethod
    def philox(self, words: np.ndarray) -> np.ndarray:
        """Philox4x32-10 of (count, 6) counter+key words: (count, 4) (known-answer tests)."""

    @abstractmethod
    def beta_draws(self, a: np.ndarray, b: np.ndarray, seed: int) -> np.ndarray:
        """One Beta(a[i], b[i]) sample each (a, b >= 1), drawn as the Thompson-sampling kernels
        draw them (kernel.cu, beta_draws): the sampler's tests."""

    def asnumpy(self, a: Any) -> np.ndarray:
        return np.asarray(a)

    def synchronize(self) -> None:  # noqa: B027 (a no-op where calls return when done)
        """Wait for the launches in flight."""


# ---------------------------------------------------------------------------- CUDA


class CudaDevice(Device):
    """The current CUDA device, through CuPy (the ``gpu`` extra). ``block``: threads a block;
    ``maxrregcount``: a cap on registers per thread (NVRTC's ``--maxrregcount``; None: the
    compiler's choice); ``defines``: kernel.cu's compile-time switches (``CAI_LOG_TEST=1``,
    ``CAI_FP64=1``); ``reduction``: one of REDUCTIONS.
    All four are there to be measured (benchmarks/bench_gpu.py)."""

    launch_work = 1 << 31
    checkpoint_bytes = 1 << 30
    in_flight = 1
    BLOCK = 128
    #: Threads a block of reduce_checkpoints (a multiple of 32: its warps merge by shuffles).
    REDUCE_BLOCK = 256

    def __init__(self, *, block: int = BLOCK, maxrregcount: int | None = None,
                 defines: Sequence[str] = (), reduction: str | None = None) -> None:  # fmt: skip
        super().__init__(reduction=reduction)
        self.block = int(block)
        self.options: tuple[str, ...] = ("-std=c++17", *(f"-D{d}" for d in defines))
        if maxrregcount is not None:
            self.options += (f"--maxrregcount={int(maxrregcount)}",)
        try:
            import cupy
        except ImportError:
            raise GpuUnavailable(
                'CuPy is not installed (pip install "corraoi[gpu]", for CUDA 13)'
            ) from None
        try:
            count = int(cupy.cuda.runtime.getDeviceCount())
        except Exception as exc:  # CuPy raises its own runtime errors without a driver
            first = (str(exc).strip().splitlines() or [""])[0]
            raise GpuUnavailable(f"no CUDA device ({type(exc).__name__}: {first})") from None
        if count < 1:
            raise GpuUnavailable("no CUDA device found")
        self.xp = cupy
        props = cupy.cuda.runtime.getDeviceProperties(cupy.cuda.Device().id)
        raw = props.get("name", b"CUDA device")
        self.name = raw.decode() if isinstance(raw, bytes) else str(raw)
        #: Blocks a reduce_checkpoints launch aims at, its checkpoints together: 32 for each
        #: multiprocessor (several rounds of the 3 it holds at once at 74 registers a thread).
        self.reduce_blocks = 32 * int(props.get("multiProcessorCount", 132))

    def _compile(self, K: int, family: str, capture: bool = False) -> Any:
        import cupy

        options = (*self.options, f"-DKARMS={K}", f"-DCAI_FAMILY={family_id(family)}",
                   *(("-DCAI_CAPTURE=1",) if capture else ()))  # fmt: skip
        mod = cupy.RawModule(code=source(), options=options)
        mod.compile()  # NVRTC, or CuPy's on-disk cache
        return mod

    def _args(self, args: ArgList) -> tuple[Any, ...]:
        conv = {"i": np.int32, "q": np.int64, "Q": np.uint64, "d": np.float64}
        return tuple(v if kind == "p" else conv[kind](v) for kind, v in args)

    def launch(self, K: int, family: str, entry: str, runs: int, args: ArgList, *,
               capture: bool = False) -> None:  # fmt: skip
        func = self.module(K, family, capture).get_function(entry)
        blocks = (runs + self.block - 1) // self.block
        func((blocks,), (self.block,), self._args(args))

    def reduce(self, K: int, family: str, nck: int, runs: int, args: ArgList) -> None:
        func = self.module(K, family).get_function("reduce_checkpoints")
        per_checkpoint = max(1, min((runs + self.REDUCE_BLOCK - 1) // self.REDUCE_BLOCK,
                                    -(-self.reduce_blocks // nck)))  # fmt: skip
        func((nck, per_checkpoint), (self.REDUCE_BLOCK,), self._args(args))

    def mark(self) -> Any:
        return self.xp.cuda.get_current_stream().record()

    def wait(self, mark: Any) -> None:
        mark.synchronize()

    def philox(self, words: np.ndarray) -> np.ndarray:
        import cupy

        count = int(words.shape[0])
        inp = cupy.asarray(np.ascontiguousarray(words, dtype=np.uint32))
        out = cupy.zeros((count, 4), dtype=cupy.uint32)
        func = self.module(1, FAMILIES[0]).get_function("philox_kat")
        func(((count + 127) // 128,), (128,), (inp, out, np.int32(count)))
        return cupy.asnumpy(out)

    def beta_draws(self, a: np.ndarray, b: np.ndarray, seed: int) -> np.ndarray:
        import cupy

        count = int(len(a))
        da = cupy.asarray(np.ascontiguousarray(a, dtype=np.float64))
        db = cupy.asarray(np.ascontiguousarray(b, dtype=np.float64))
        out = cupy.zeros(count)
        func = self.module(1, "ts_beta").get_function("beta_draws")
        func(((count + 127) // 128,), (128,), (da, db, np.int32(count), np.uint64(seed), out))
        return cupy.asnumpy(out)

    def asnumpy(self, a: Any) -> np.ndarray:
        return self.xp.asnumpy(a)

    def synchronize(self) -> None:
        self.xp.cuda.Device().synchronize()


# ---------------------------------------------------------------------------- emulation


def host_compiler() -> str | None:
    """The host C++ compiler the emulated device uses, or None."""
    for name in (os.environ.get("CXX"), "g++", "c++", "clang++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


class EmulatedDevice(Device):
    """kernel.cu compiled for the host CPU: the GPU backend's code where no GPU is."""

    name = "emulated on the CPU"
    FLAGS = ("-O2", "-std=c++17", "-fopenmp", "-shared", "-fPIC", "-x", "c++")

    def __init__(self, *, defines: Sequence[str] = (), reduction: str | None = None) -> None:
        super().__init__(reduction=reduction)
        cxx = host_compiler()
        if cxx is None:
            raise GpuUnavailable(f"{DEVICE_ENV}=emulate needs a C++ compiler (g++ or $CXX)")
        self._cxx = cxx
        self._defines = tuple(f"-D{d}" for d in defines)

    def _module_key(self, K: int, family: str, capture: bool = False) -> Any:
        return (K, capture)  # one library per K holds every family

    def _compile(self, K: int, family: str, capture: bool = False) -> Any:
        return ctypes.CDLL(str(self.build(K, capture=capture)))

    def build(self, K: int, *, capture: bool = False) -> Path:
        """The emulation library for ``K`` arms (``capture``: the capture module): from the
        kernel cache when intact, else compiled once (one process compiles, the others wait
        for it)."""
        from corraoi.engine import kernel_cache

        text = source()
        flags = (*self.FLAGS, *self._defines, f"-DKARMS={K}",
                 *(("-DCAI_CAPTURE=1",) if capture else ()))  # fmt: skip
        digest = hashlib.sha256("\0".join((text, self._cxx, *flags)).encode()).hexdigest()[:16]
        folder = kernel_cache.folder("gpu-emulation")  # else the system's temp folder
        lib = folder / f"kernel-K{K}{'-capture' if capture else ''}-{digest}.so"
        if _intact(lib):  # checked before it is mapped: a cut-short library is never loaded
            return lib
        with kernel_cache.locked(folder, lib.stem):  # two processes, a fresh cache: one compiles
            if _intact(lib):
                return lib
            if lib.exists():
                if kernel_cache.on_compile is not None:
                    kernel_cache.on_compile(f"the cached GPU-emulation library {lib.name} is "
                                            "damaged or unverified; rebuilding it")  # fmt: skip
            return self.compile_to(lib, flags)

    def compile_to(self, lib: Path, flags: tuple[str, ...]) -> Path:
        """Compile the library into ``lib`` with ``flags`` (written aside, then moved in)."""
        folder = lib.parent
        fd, tmp = tempfile.mkstemp(prefix=lib.name, suffix=".partial", dir=folder)
        os.close(fd)
        try:
            done = subprocess.run([self._cxx, *flags, str(SOURCE_PATH), "-o", tmp],
                                  capture_output=True, text=True)  # fmt: skip
            if done.returncode != 0:
                first = (done.stderr.strip().splitlines() or ["(no output)"])[0]
                raise GpuUnavailable(f"{self._cxx} could not compile {SOURCE_PATH}: {first}")
            data = Path(tmp).read_bytes()
            os.replace(tmp, lib)  # atomic: a library exists only when complete
            _sums(lib).write_text(hashlib.sha256(data).hexdigest() + "\n", encoding="ascii")
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return lib

    @staticmethod
    def _args(args: ArgList) -> list[Any]:
        out: list[Any] = []
        for kind, v in args:
            if kind == "p":
                if not v.flags.c_contiguous:
                    raise ValueError("kernel arrays must be C-contiguous")
                out.append(ctypes.c_void_p(v.ctypes.data))
            else:
                conv = {"i": ctypes.c_int32, "q": ctypes.c_int64, "Q": ctypes.c_uint64,
                        "d": ctypes.c_double}  # fmt: skip
                out.append(conv[kind](v))
        return out

    def launch(self, K: int, family: str, entry: str, runs: int, args: ArgList, *,
               capture: bool = False) -> None:  # fmt: skip
        func = getattr(self.module(K, family, capture), entry)
        func.restype = None
        func(*self._args(args))

    def reduce(self, K: int, family: str, nck: int, runs: int, args: ArgList) -> None:
        func = self.module(K, family).reduce_checkpoints
        func.restype = None
        func(*self._args(args))

    def philox(self, words: np.ndarray) -> np.ndarray:
        inp = np.ascontiguousarray(words, dtype=np.uint32)
        out = np.zeros((inp.shape[0], 4), dtype=np.uint32)
        func = self.module(1, FAMILIES[0]).philox_kat
        func.restype = None
        func(*self._args([("p", inp), ("p", out), ("i", inp.shape[0])]))
        return out

    def beta_draws(self, a: np.ndarray, b: np.ndarray, seed: int) -> np.ndarray:
        da = np.ascontiguousarray(a, dtype=np.float64)
        db = np.ascontiguousarray(b, dtype=np.float64)
        out = np.zeros(len(da))
        func = self.module(1, "ts_beta").beta_draws
        func.restype = None
        func(*self._args([("p", da), ("p", db), ("i", len(da)), ("Q", seed), ("p", out)]))
        return out


def _sums(lib: Path) -> Path:
    return lib.with_name(lib.name + ".sha256")


def _intact(lib: Path) -> bool:
    """Whether a cached library is the one compiled: its bytes hash to the sha256 written
    beside it when it was (a truncated library, mapped, dies of SIGBUS when it is called)."""
    try:
        want = _sums(lib).read_text(encoding="ascii").strip()
        return hashlib.sha256(lib.read_bytes()).hexdigest() == want
    except OSError:
        return False


# ---------------------------------------------------------------------------- choosing


#: the devices made in this process, by kind (a test swaps in an empty one)
DEVICES: dict[str, Device] = {}
_DEVICE_LOCK = threading.Lock()


def get_device() -> Device:
    """The device of this process (made once): ``$CORRAOI_GPU_DEVICE`` ``cuda`` (default) or
    ``emulate``. Raises :class:`GpuUnavailable` with the reason when there is none."""
    return device_of(os.environ.get(DEVICE_ENV, "cuda").strip().lower() or "cuda")


def device_of(kind: str) -> Device:
    """The device ``kind`` ("cuda" or "emulate") of this process, made once."""
    with _DEVICE_LOCK:
        device = DEVICES.get(kind)
        if device is None:
            if kind == "emulate":
                device = EmulatedDevice()
            elif kind == "cuda":
                device = CudaDevice()
            else:
                raise GpuUnavailable(f"{DEVICE_ENV}={kind!r}: expected 'cuda' or 'emulate'")
            DEVICES[kind] = device
        return device
