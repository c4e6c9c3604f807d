"""JAX's persistent compilation cache for jaxcoag runs (``jaxcoag.enable_compilation_cache``).

A compiled solve of the binned engine takes seconds to tens of seconds to build (XLA compile of
the diffrax loop with the kernel inside); JAX can store the compiled executables on disk and load
them in the next process instead of compiling again. ``jaxcoag run`` and ``jaxcoag sweep`` switch
this on by default (``--no-cache`` or ``JAXCOAG_CACHE_DIR=off`` turn it off).

References: JAX documentation, "Persistent compilation cache" (config options
``jax_compilation_cache_dir``, ``jax_persistent_cache_min_compile_time_secs``,
``jax_persistent_cache_min_entry_size_bytes``).
"""

from __future__ import annotations

import os
import tempfile
import warnings

__all__ = ["enable_compilation_cache", "default_cache_dir", "CACHE_ENV", "CACHE_OFF"]

#: Environment variable naming the cache directory (or one of :data:`CACHE_OFF` to switch it off).
CACHE_ENV = "JAXCOAG_CACHE_DIR"
#: Values of ``$JAXCOAG_CACHE_DIR`` that switch the cache off.
CACHE_OFF = ("off", "0", "none", "false", "no")


def default_cache_dir():
    """The cache directory ``enable_compilation_cache()`` uses: ``$JAXCOAG_CACHE_DIR`` if set
    (None when it says off: "off", "0", "none", "false", "no"), else ``~/.cache/jaxcoag/jax``
    (``$XDG_CACHE_HOME/jaxcoag/jax`` when XDG_CACHE_HOME is set)."""
    env = os.environ.get(CACHE_ENV)
    if env is not None and env.strip():
        return None if env.strip().lower() in CACHE_OFF else os.path.expanduser(env.strip())
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "jaxcoag", "jax")


def _writable_dir(path):
    """None if ``path`` is (made) a directory that accepts a new file, else the reason (str)."""
    try:
        os.makedirs(path, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".jaxcoag-cache-probe-", dir=path)
        os.close(fd)
        os.remove(tmp)
    except OSError as e:
        return e.strerror or type(e).__name__
    return None


def enable_compilation_cache(path=None, *, min_compile_time_secs=0.0):
    """Switch on JAX's persistent compilation cache, so a second process does not compile again.

    Compiled XLA executables whose compilation took at least ``min_compile_time_secs`` are
    written to ``path`` and read back by later processes with the same program, JAX version,
    backend and flags (the cache key covers all of them, so a stale entry is never used).
    ``jaxcoag run`` and ``jaxcoag sweep`` call this by default; ``--no-cache`` (or
    ``JAXCOAG_CACHE_DIR=off``) turns it off.

    Arguments:
        path: cache directory (created if missing). None: ``$JAXCOAG_CACHE_DIR`` if set (the
            values off/0/none/false/no switch the cache off and return None), else
            ``~/.cache/jaxcoag/jax``.
        min_compile_time_secs: programs that compiled faster than this [s] are not written
            (``jax_persistent_cache_min_compile_time_secs``). Default 0: everything. A small
            binned run compiles ~130 programs of 5-500 ms each (the solve is split into many
            of them), none above JAX's own default threshold of 1 s, so with that default
            nothing was cached; caching all of them took the second ``jaxcoag run`` of a
            17-bin box from 10 s to 6 s after import (about 0.5 MB on disk).

    Returns:
        the absolute cache directory in use (str), or None when the cache stays off: switched off
        by the environment, or the directory cannot be created or written (then a
        ``RuntimeWarning`` says why and the run continues uncached - never an error).

    Sets JAX's public config options ``jax_compilation_cache_dir``,
    ``jax_persistent_cache_min_compile_time_secs`` and ``jax_persistent_cache_min_entry_size_bytes``
    (-1: no size threshold); a process that used another cache directory before is switched to
    this one (``jax.experimental.compilation_cache.compilation_cache.reset_cache``). Programs
    already compiled in this process stay in JAX's in-memory cache and are not written. The cache
    is trusted code: do not point it at a directory others can write.
    """
    import jax

    if path is None:
        path = default_cache_dir()
        if path is None:
            return None
    path = os.path.abspath(os.path.expanduser(os.fspath(path)))
    why = _writable_dir(path)
    if why is not None:
        warnings.warn(f"jaxcoag: the compilation cache directory {path!r} cannot be written ({why}); running "
                      f"without the persistent compilation cache (set {CACHE_ENV} to a writable directory, or "
                      "--no-cache).", RuntimeWarning, stacklevel=2)
        return None
    try:
        if jax.config.jax_compilation_cache_dir not in (None, path):  # another directory was in use
            from jax.experimental.compilation_cache import compilation_cache as _cc

            _cc.reset_cache()
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_secs))
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    except (AttributeError, ValueError, TypeError) as e:  # an option missing in another JAX version
        warnings.warn(f"jaxcoag: could not switch on JAX's persistent compilation cache ({e}); running uncached.",
                      RuntimeWarning, stacklevel=2)
        return None
    return path
