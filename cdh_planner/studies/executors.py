"""Where a study's calls run: in this process (``SerialExecutor``) or on Ray actors
(``RayExecutor``: a local Ray started here, or a cluster at ``address``).

Both have ``workers`` and ``map(job, calls, deadline=None)``: it yields ``(i, answer)`` as the
calls finish (any order), each call exactly once, with ``i`` its position in ``calls``;
``run_call(context, call)`` of the job's module answers it, the context built once per
worker by ``make_context(job)``. Past ``deadline`` (time.monotonic, s) no call is started and
the ones in flight are abandoned: the caller sees fewer answers (a bound, not an error).

Ray is imported only by ``RayExecutor``: nothing else in the package needs it.
"""

import os
import socket
import time

from ..errors import InputError, clip, exception_line
from ..progress import stderr_held
from . import workspace

MAX_LOST = 100            # answers lost to dead workers before the map gives up (each retried)
IN_FLIGHT_PER_WORKER = 2  # calls queued per actor: one running, one ready
QUIET = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=False,
             ignore_reinit_error=True)
OBJECT_STORE_BYTES = 100 * 2 ** 20  # a local Ray's: a call's answer is < 1 MB (5000 poses)


def default_workers():
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


class SerialExecutor:
    """Every call in this process, in order (small runs, tests, no Ray)."""

    workers = 1

    def __init__(self, module=workspace):
        self.module = module
        self._key, self._context = None, None

    def map(self, job, calls, deadline=None, clock=time.monotonic):
        if self._key is not job:
            self._key, self._context = job, self.module.make_context(job)
        for i, call in enumerate(calls):
            if deadline is not None and clock() > deadline:
                return
            yield i, self.module.run_call(self._context, call)

    def close(self):
        pass


class RayExecutor:
    """Calls on ``workers`` Ray actors, each of which builds a job's context once and then
    takes its calls. A worker killed mid-call: Ray restarts the actor and re-runs the call
    (``max_task_retries``); if that fails too the call is queued again here, so each call is
    answered once. ``address``: a running cluster ("HOST:PORT", "auto"); None starts a local
    Ray of ``workers`` CPUs for this process."""

    def __init__(self, workers, address=None, module=workspace):
        try:
            import ray  # the one import of Ray in the package
        except ImportError:
            raise InputError("--workers", workers, "needs Ray, which is not installed "
                                                   "(pip install ray==2.60.0), or run with --no-ray") from None

        self.ray, self.workers, self.module = ray, int(workers), module
        started = time.perf_counter()
        if address:
            connect(ray, address)
        else:
            start_local_ray(self.workers)
        self.start_s = time.perf_counter() - started
        worker = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(_Worker)
        self.actors = [worker.remote(module.__name__) for _ in range(self.workers)]
        self._job, self._job_ref, self._job_key = None, None, 0

    def pids(self):
        """The worker processes' ids (tests kill one)."""
        return self.ray.get([a.pid.remote() for a in self.actors])

    def cpu_seconds(self):
        """Each worker process's CPU time so far, s (benchmarks: how much of a core each got)."""
        return self.ray.get([a.cpu_seconds.remote() for a in self.actors])

    def map(self, job, calls, deadline=None, clock=time.monotonic):
        ray = self.ray
        if self._job is not job:  # one copy of the job in the object store per job
            self._job, self._job_ref, self._job_key = job, ray.put(job), self._job_key + 1
        job_key = self._job_key
        queue = list(range(len(calls)))[::-1]
        pending, lost = {}, 0  # ref -> (call index, actor)
        load = {a: 0 for a in self.actors}
        while queue or pending:
            while queue and (deadline is None or clock() <= deadline):
                actor = min(load, key=load.get)
                if load[actor] >= IN_FLIGHT_PER_WORKER:
                    break
                i = queue.pop()
                ref = actor.run.remote(job_key, self._job_ref, calls[i])
                pending[ref], load[actor] = (i, actor), load[actor] + 1
            if not pending:
                return  # past the deadline with calls left: the caller counts them
            timeout = None if deadline is None else max(0.0, deadline - clock()) + 0.05
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=timeout)
            if not ready:
                return  # the deadline passed with calls in flight: abandoned
            ref = ready[0]
            i, actor = pending.pop(ref)
            load[actor] -= 1
            try:
                answer = ray.get(ref)
            except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError,
                    ray.exceptions.ObjectLostError):
                lost += 1
                if lost > MAX_LOST:
                    raise RuntimeError(f"{lost} calls lost to dead Ray workers") from None
                queue.append(i)  # once more, on whichever actor is free
                continue
            except ray.exceptions.RayTaskError as exc:  # the call raised: re-raise its error
                raise exc.as_instanceof_cause() from None
            yield i, answer

    def close(self):
        """Disconnect this driver: Ray ends the actors it made (they are not detached).
        No ``ray.kill`` first: killing actors with calls in flight (Ctrl-C mid-run) makes
        the raylet print a coloured "will be retried" line per call on stdout."""
        self.ray.shutdown()


class _Worker:
    """A Ray actor: the context of the current job, then calls. One BLAS thread: a worker
    is one core's share (more threads per worker only contend with the other workers)."""

    def __init__(self, module_name):
        import importlib

        from threadpoolctl import threadpool_limits

        self._limits = threadpool_limits(limits=1)  # kept for the actor's life
        self.module = importlib.import_module(module_name)
        self.key, self.context = None, None

    def pid(self):
        return os.getpid()

    def cpu_seconds(self):
        return time.process_time()

    def run(self, job_key, job, call):
        if self.key != job_key:
            self.key, self.context = job_key, self.module.make_context(job)
        return self.module.run_call(self.context, call)


AUTH_MODE = "RAY_AUTH_MODE"
TOKEN_SOURCES = "RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token"
TOKEN_FIX = "set RAY_AUTH_TOKEN to the head's `ray get-auth-token`"
START_FIX = "start it with `ray start --head --port=PORT` or leave out --ray-address"
CONNECT_TIMEOUT_S = 5.0   # s: a cluster's GCS port that does not accept in this is not there
GCS_WAIT = "RAY_gcs_server_port_wait_time_s"   # Ray's connect budget (about 1 s a try)
FIRST_TRY_S = 3           # s: the try without a token, when one is at hand


def connect(ray, address):
    """``ray.init`` on the cluster at ``address``, with a token if the cluster asks for one
    and one is at hand where Ray's own CLI looks (RAY_AUTH_TOKEN, the file
    RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token; Ray's loader reads them): ray.init alone sends
    none to an explicit address. A driver must match the cluster (a token-mode driver on a
    cluster without tokens loses its workers), so with RAY_AUTH_MODE unset it first tries
    without one, briefly, and turns token mode on only when the cluster answered
    "Unauthenticated". A refused connection: InputError naming --ray-address, the cause
    and the fix, in one line."""
    reachable(address)
    mode = os.environ.get(AUTH_MODE)
    token = token_source() if mode is None or mode.lower() == "token" else None
    if mode is None and token is not None:
        said = _try_init(ray, address, {GCS_WAIT: str(FIRST_TRY_S)})
        if said is not None and "Unauthenticated" not in said:   # slow, or not tokens:
            ray.shutdown()                                       # Ray's usual budget
            said = _try_init(ray, address, {})
        if said is None:
            return None
        ray.shutdown()
        if "Unauthenticated" not in said:
            raise InputError("--ray-address", address, refusal(said, None))
        _token_mode()
    said = _try_init(ray, address, {})
    if said is not None:
        raise InputError("--ray-address", address, refusal(said, token))
    return token


def reachable(address, timeout_s=CONNECT_TIMEOUT_S):
    """InputError naming --ray-address unless a HOST:PORT address accepts a TCP connection
    within ``timeout_s`` (s): ray.init would retry a closed port for minutes. Other
    addresses ("auto", "ray://...") are left to Ray."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or "/" in host:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise InputError("--ray-address", address, f"nothing answers there "
                         f"({exc.strerror or type(exc).__name__}): {START_FIX}") from None


def _try_init(ray, address, env):
    """None once ray.init connected, else what it said (its exception and Ray's lines on
    stderr meanwhile). ``env``: variables set for this attempt only."""
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        with stderr_held() as held:   # Ray's C++ retries, a line a second
            ray.init(address=address, **QUIET)
        return None
    except Exception as exc:  # noqa: BLE001 - ConnectionError, RuntimeError, AuthenticationError
        return f"{held.text}\n{exception_line(exc, 120) if str(exc) else type(exc).__name__}"
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def token_source():
    """Where a Ray token is at hand for this process (the variable's name or the default
    file), None without one."""
    try:  # Ray's own loader (what ray.scripts.scripts start asks)
        from ray._raylet import AuthenticationTokenLoader
    except ImportError:  # another Ray: its ray.init decides alone
        return None
    loader = AuthenticationTokenLoader.instance()
    found = loader.has_token(ignore_auth_mode=True)
    loader.reset_cache()   # a cached token makes this driver ask its workers for it
    if not found:
        return None
    for name in ("RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH"):
        if os.environ.get(name):
            return name
    return "~/.ray/auth_token"


def _token_mode():
    """Token authentication on for this process (what ``ray start --head`` does when a
    token is at hand)."""
    from ray._private.authentication import authentication_token_setup as setup
    from ray._raylet import AuthenticationTokenLoader
    setup._enable_token_auth()
    AuthenticationTokenLoader.instance().reset_cache()


def refusal(said, token):
    """The one line of a refused connection: cause and fix. ``said``: what ray.init said
    (``_try_init``); ``token``: ``token_source()`` if one was sent."""
    unauthenticated = "Unauthenticated" in said or "no authentication token" in said
    if unauthenticated and token is None:
        return f"token required, none found ({TOKEN_SOURCES}): {TOKEN_FIX}"
    if unauthenticated:
        return f"the cluster refused the token of {token}: {TOKEN_FIX}"
    cause = said.strip().splitlines()[-1] if said.strip() else "no answer"
    return f"cannot connect ({clip(cause, 70)}): {START_FIX}"


def start_local_ray(workers):
    """Start a Ray of ``workers`` CPUs for this process (its workers inherit PYTHONPATH):
    no dashboard, no usage statistics, no metrics, a small object store
    (benchmarks/ray_startup.py measures each). "local": a new Ray even when a cluster's
    address file is left in /tmp/ray."""
    import ray

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # read by ray.init: no prompt, no upload
    ray.init(address="local", num_cpus=workers, object_store_memory=OBJECT_STORE_BYTES,
             _system_config={"enable_metrics_collection": False}, **QUIET)


def make_executor(workers=None, address=None, ray=True, module=workspace):
    """The executor of the commands' options: ``SerialExecutor`` without Ray (``ray``
    False), else a ``RayExecutor`` of ``workers`` actors (default: the cores)."""
    if not ray:
        return SerialExecutor(module)
    return RayExecutor(workers or default_workers(), address=address, module=module)
