"""Import Open3D, working around a missing system libusb-1.0.

The open3d 0.20 wheel links against libusb-1.0.so.0 (RealSense support).  If the
Debian package libusb-1.0-0 is not installed, `import open3d` fails.  The PyPI
package `libusb-package` ships a copy with the same soname; loading it with
RTLD_GLOBAL before importing open3d satisfies the dependency without touching
system paths.
"""
import ctypes
import os


def _preload_libusb():
    try:
        ctypes.CDLL("libusb-1.0.so.0", mode=ctypes.RTLD_GLOBAL)
        return "system"
    except OSError:
        pass
    try:
        import libusb_package  # type: ignore
    except ImportError:
        return None
    d = os.path.dirname(libusb_package.__file__)
    for name in ("libusb-1.0.so", "libusb-1.0.so.0"):
        p = os.path.join(d, name)
        if os.path.exists(p):
            ctypes.CDLL(p, mode=ctypes.RTLD_GLOBAL)
            return p
    return None


LIBUSB_SOURCE = _preload_libusb()

try:
    import open3d as o3d  # noqa: E402
    import open3d.core as o3c  # noqa: E402

    # Open3D prints its warnings on stdout; keep stdout clean for JSON output
    # unless O3D_VERBOSE=1 is set.
    if os.environ.get("O3D_VERBOSE", "") in ("", "0"):
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
except ImportError as e:  # pragma: no cover
    raise SystemExit(
        f"error: cannot import open3d ({e}).\n"
        "Install it in the venv (see README.md); if the error mentions libusb-1.0.so.0, "
        "`pip install libusb-package` (or install Debian libusb-1.0-0)."
    )
