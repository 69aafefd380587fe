"""Stopping long work on Ctrl-C (SIGINT) and SIGTERM: promptly, inside compiled backends too.

Python runs a signal's handler only between bytecodes of the main thread. While a compiled
backend runs -- Clarabel's interior point, HiGHS's simplex or IPX -- nothing of Python runs, and
a Ctrl-C waits for the backend to finish (minutes on a large LP). Two tools here:

* :func:`deferred` wraps a backend call: while it runs, SIGINT and SIGTERM only set a flag (no
  exception is thrown into a backend's callback), the backend's own hook reads it
  (:func:`stop_asked`: Clarabel's termination callback, HiGHS's interrupt callbacks through a
  cancel) and stops at its next iteration; on leaving, the signal is handed to the handler that
  was in place before (``KeyboardInterrupt`` for Ctrl-C, the command line's for SIGTERM).
* A **stop request** that outlives the exception: the command line records the signal
  (:func:`request`) before raising ``KeyboardInterrupt``. A solver that catches the interrupt
  to return what it has (value iteration's "interrupted" status, relaxation 2's best bound so
  far) returns; the next step of the command -- a progress phase, the next policy of ``bound
  --policy``, the next point of a study -- calls :func:`check`, which raises again, so the whole
  command stops, not only the step in progress. A library caller never calls :func:`request`:
  there Ctrl-C stops the solve in progress, as before.
* **Not inside the compiler**: a signal that arrives while numba compiles a kernel (or loads
  it from its cache) is not turned into an exception there -- raised inside numba's or
  llvmlite's Python code it could leave their lock held and the command hanging. The command
  line's handler (:func:`in_compiler`) hands it to :func:`deliver_later`, which sends it again
  once the compilation is over: the stop then takes the rest of the compilation (seconds).
* **Not where an exception is lost**: a signal that arrives inside a finalizer (``__del__``)
  or a weak reference's callback (run by the garbage collector at any allocation) would raise
  where Python cannot propagate it: it prints "Exception ignored in ..." with a traceback and
  the stop is lost until the next :func:`check`. :func:`not_raisable` finds those frames too
  (``__del__``, the standard library's weak containers), and the handler delivers the signal
  later, as for the compiler; for any other callback, :func:`redeliver_lost` catches the lost
  interrupt (no traceback printed) and sends the signal again.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["request", "requested", "clear", "check", "deferred", "stop_asked", "in_thread", "in_compiler",
           "in_finalizer", "not_raisable", "deliver_later", "redeliver_lost", "STOP_SIGNALS"]

#: The signals that stop a command.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_requested: list[int] = []  # the signal of a stop request (the command line's), first first
_pending: list[int] = []  # signals noted inside deferred() blocks


def request(signum: int) -> None:
    """Record a stop request (the command line's signal handlers call this)."""
    _requested.append(int(signum))


def requested() -> int | None:
    """The signal of the stop request, or None."""
    return _requested[0] if _requested else None


def clear() -> None:
    """Forget a stop request (at the end of a command)."""
    _requested.clear()
    _pending.clear()
    _later.clear()


def check() -> None:
    """Raise ``KeyboardInterrupt`` when a stop was requested: called between the steps of long
    work, so that work a solver returned from after an interrupt does not go on."""
    if _requested:
        raise KeyboardInterrupt


def stop_asked() -> bool:
    """A stop was asked: a signal inside a :func:`deferred` block, or a stop request."""
    return bool(_pending or _requested)


def _deliver(signum: int, handler) -> None:
    """Hand a signal noted inside :func:`deferred` to the handler that was in place before."""
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        signal.raise_signal(signum)  # the default action (the handler is restored already)


@contextmanager
def deferred() -> Iterator[Callable[[], bool]]:
    """Run a block with SIGINT / SIGTERM turned into a flag; yields :func:`stop_asked`.

    Outside the main thread (where handlers cannot be set) it only yields :func:`stop_asked`.
    Blocks nest: the inner one leaves a signal for the outer one to deliver.
    """
    if threading.current_thread() is not threading.main_thread():
        yield stop_asked
        return
    outer = bool(_handlers)
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    if not outer:
        for s in STOP_SIGNALS:
            if signal.getsignal(s) != signal.SIG_IGN:
                signal.signal(s, _note)
        _handlers.update(previous)
    try:
        yield stop_asked
    finally:
        if not outer:
            for s, h in _handlers.items():
                signal.signal(s, h)
            saved = dict(_handlers)
            _handlers.clear()
            if _pending:
                signum = _pending[0]
                _pending.clear()
                _deliver(signum, saved[signum])


_handlers: dict[int, object] = {}


def _note(signum: int, frame) -> None:
    _pending.append(signum)


def in_thread(fn: Callable[[], object], poll: float = 0.1) -> object:
    """``fn()`` run in a daemon thread while this one waits for it, stoppable.

    For a compiled call that offers no hook to stop it (Clarabel inside cvxpy) but releases the
    GIL: inside a :func:`deferred` block, a stop asked while it runs returns control at once by
    ``KeyboardInterrupt`` (the handler in place before the block is called on leaving it); the
    abandoned call finishes in the background (or ends with the process). Its exception, if it
    raises one, is raised here.
    """
    box: dict[str, object] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True, name="wncs-lp-backend")
    with deferred() as stop:
        t.start()
        while t.is_alive():
            t.join(poll)
            if stop():
                break
    if t.is_alive():  # stopped, and the handler in place let it go on: nothing to return
        raise KeyboardInterrupt
    if "error" in box:
        raise box["error"]  # type: ignore[misc]
    return box.get("value")


# ----------------------------------------------------------------------------- not inside the compiler
#: Packages whose Python code must not be interrupted by an exception: numba's compiler and
#: llvmlite hold a lock and half-built objects while a kernel compiles (a ``KeyboardInterrupt``
#: raised there left the process hanging on the lock, or printed a traceback from a ``__del__``).
COMPILER_PACKAGES = ("numba", "llvmlite")

_later: list[int] = []  # signals waiting for the main thread to leave the compiler


def _on_stack(frame, test: Callable[[object], bool]) -> bool:
    """``test`` holds for the frame or one of its callers."""
    while frame is not None:
        if test(frame):
            return True
        frame = frame.f_back
    return False


def _compiling(frame) -> bool:
    return frame.f_globals.get("__name__", "").split(".", 1)[0] in COMPILER_PACKAGES


def _finalizing(frame) -> bool:
    return (frame.f_code.co_name == "__del__" or frame.f_globals.get("__name__", "") in FINALIZER_MODULES
            or frame.f_code is _lost_interrupt.__code__)


def in_compiler(frame) -> bool:
    """The frame (a signal handler's ``frame``) or one of its callers runs numba's or llvmlite's
    Python code: a kernel is being compiled (or loaded from numba's cache)."""
    return _on_stack(frame, _compiling)


#: Modules whose functions the garbage collector calls as weak reference callbacks: an exception
#: raised in one is printed as "Exception ignored in ..." and dropped.
FINALIZER_MODULES = ("weakref", "_weakrefset")


def in_finalizer(frame) -> bool:
    """The frame or one of its callers is a finalizer (``__del__``) or a weak reference's
    callback: an exception raised there is not propagated, only printed."""
    return _on_stack(frame, _finalizing)


def not_raisable(frame) -> bool:
    """A signal handler called on this frame must not raise: the main thread is compiling
    (:func:`in_compiler`) or finalizing (:func:`in_finalizer`); one walk of the stack."""
    return _on_stack(frame, lambda f: _compiling(f) or _finalizing(f))


def deliver_later(signum: int, poll: float = 0.02) -> None:
    """Send ``signum`` to this process again once the main thread can take an exception.

    For a signal handler that found the main thread compiling or finalizing
    (:func:`not_raisable`): it returns without raising, and a watcher thread re-sends the signal
    when no such frame is left on the main thread's stack, so the handler then raises where it is
    safe -- within a moment. A stop already handled meanwhile (:func:`clear`) sends nothing.
    """
    import os
    import sys

    if _later:  # a watcher is already waiting: one delivery is enough
        return
    _later.append(int(signum))
    main = threading.main_thread().ident

    def watch() -> None:
        while _later:
            if not not_raisable(sys._current_frames().get(main)):
                if _later:
                    _later.clear()
                    os.kill(os.getpid(), signum)
                return
            threading.Event().wait(poll)

    threading.Thread(target=watch, daemon=True, name="wncs-lp-stop-later").start()


@contextmanager
def redeliver_lost() -> Iterator[None]:
    """Within the block, a ``KeyboardInterrupt`` that Python could not propagate (raised by a stop
    request's handler inside a finalizer or callback it did not recognise) prints nothing and
    its signal is sent again (:func:`deliver_later`), so the stop is not lost. Other
    unraisable exceptions go to the hook in place before."""
    import sys

    _hooks.append(sys.unraisablehook)
    sys.unraisablehook = _lost_interrupt
    try:
        yield
    finally:
        sys.unraisablehook = _hooks.pop()


_hooks: list = []  # the unraisable hooks redeliver_lost() replaced, innermost last


def _lost_interrupt(unraisable) -> None:
    # not_raisable() knows this function: a signal sent again while it runs waits for its end
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _requested:
        deliver_later(_requested[0])
        return
    _hooks[-1](unraisable)
