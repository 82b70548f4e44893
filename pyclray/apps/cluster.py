"""Scale-out on Dask distributed: the frames of an animation, many views of a scene (a data set), or
the bands of one large image, rendered by the workers of a cluster: a LocalCluster of N worker
processes, or a running cluster reached by its scheduler's address. Needs the `cluster` extra
(pip install 'pyclray[cluster]'); nothing else in pyclray imports distributed.

Warm workers. A job (the scene, the images asked, precision, device, and what a task returns) is a
WorkerPlugin registered once with Client.register_plugin: Dask pickles it once and the scheduler hands
it to every worker, and to any worker that joins later (one a nanny restarts after a crash). Its setup
opens the worker's OpenCL context and builds the program (a one-pixel render) before the first task;
the worker process then keeps them (pyclray.engine.launch.programs' caches) and the packed inputs of the scenes it
renders (pyclray.engine.scene.prepared's), so a task carries only what changes: a frame's index, a camera, a window.

Results come back to the client as tasks complete and are handed over in task order, whatever order
the workers finish in; a few tasks per worker thread are in flight, and the next is submitted as one
is handed over, so a slow consumer (a writer) holds the cluster back instead of piling results up.
An error raised on a worker is raised again in the client, the same exception with the same
one-line message. A worker that dies (a crash, a killed process, a lost machine) loses its tasks;
the scheduler runs them again on the others (up to distributed.scheduler.allowed-failures times
per task).
"""
from __future__ import annotations

import asyncio
import dataclasses
import logging
import os
import uuid
from contextlib import contextmanager, suppress

import dask
from distributed import Client, LocalCluster, WorkerPlugin, as_completed, get_worker
from distributed.scheduler import KilledWorker

from ..engine.api import render
from ..engine.queries.requests import Frame, frame_camera
from ..model.aovs import AOVS
from ..model.camera import Camera
from ..model.errors import PyclrayError, RequestError
from ..model.scene import Scene

# Seconds to wait for a scheduler to answer, and for a running cluster to have a worker.
CONNECT_TIMEOUT_S = 10
WORKERS_TIMEOUT_S = 60
# Pixels a band task of `pyclray render --workers` renders: 512x512 worth (5 MB of images at most),
# enough work to make a task's overhead (milliseconds) small, small enough to spread an image
TASK_PIXELS = 1 << 18
# Tasks in flight: 4 per worker thread (one running, one waiting there, results on their way back), at
# least 8 (short tasks need a deeper pipeline to hide the round trip; docs/benchmarks.md, "Why the
# engine does what it does"); more are submitted as results are handed over, so memory stays bounded
# whatever the length of the run
AHEAD_PER_THREAD = 4
AHEAD_MIN = 8


class ClusterError(PyclrayError, ValueError):
    """A cluster that cannot be used: a scheduler that does not answer, or has no worker."""


# -- the cluster -------------------------------------------------------------------------------
def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextmanager
def connect(workers: int | None = None, scheduler: str | None = None):
    """A dask Client: of a running cluster (`scheduler`: its address, e.g. tcp://host:8786), else of a
    new LocalCluster of `workers` processes (default: one per core) of one task thread each, closed
    on leaving the block.

    A local worker's OpenCL CPU device (PoCL) gets an equal share of this machine's cores as its
    threads (unless $POCL_CPU_MAX_CU_COUNT is set): N workers of all the cores each would only contend.
    The results do not depend on the number of threads."""
    if scheduler is not None:
        with _client_of(scheduler) as client:
            try:
                client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
            except TimeoutError:
                raise ClusterError(
                    f"--scheduler {scheduler}: the cluster has no worker (waited {WORKERS_TIMEOUT_S} s); "
                    f"start some with `dask worker {scheduler}`"
                ) from None
            yield client
        return
    workers = workers or _cores()
    threads = str(max(1, _cores() // workers))
    env = {name: os.environ.get(name, threads) for name in ("POCL_CPU_MAX_CU_COUNT", "POCL_MAX_PTHREAD_COUNT")}
    # Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536 (to hand freed memory back to the
    # system at once); that also turns off glibc's adaptive mmap threshold, so every frame's megabyte
    # buffers are mapped and faulted in anew (docs/benchmarks.md, "Why the engine does what it does").
    # The workers of a local cluster keep glibc's defaults.
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
            # no dashboard, and the scheduler's HTTP endpoints on a free port (not 8787, maybe taken)
            dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"},
            # the command reports errors itself, one line each; the workers' own logs stay quiet
            silence_logs=logging.CRITICAL, env=env,
        )
    # the client fetches results from the workers themselves, not through the scheduler
    with cluster, Client(cluster, set_as_default=False, direct_to_workers=True) as client:
        yield client


@contextmanager
def _client_of(scheduler: str):
    """A Client of the scheduler at this address, or a ClusterError of one line at once.

    A Client whose constructor fails (a malformed address, TLS without its configuration, an
    unreachable host) still runs its event loop, and its __del__ then waits twice the timeout (20 s)
    to close a connection that never was and prints a traceback: it is made here with __new__ so
    that a failed one can be marked closed and its loop stopped."""
    client = Client.__new__(Client)
    try:
        client.__init__(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except Exception as error:  # Dask raises OSError, TimeoutError, ValueError, TypeError, ...
        client.status = "closed"
        with suppress(Exception):
            client._loop_runner.stop()
        reason = " ".join(str(error).split()) or type(error).__name__
        raise ClusterError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there ({reason})") from None
    with client:
        yield client


def describe(client: Client) -> str:
    """"2 workers" (and the scheduler's address for a cluster that is not local)."""
    count = len(client.nthreads())
    where = "" if isinstance(client.cluster, LocalCluster) else f" at {client.scheduler.address}"
    return f"{count} worker{'s' if count != 1 else ''}{where}"


# -- the job on each worker --------------------------------------------------------------------
class Job(WorkerPlugin):
    """What every task of one run shares, held by each worker for the run's duration: the scene (it
    travels once per worker, inside this plugin), the images asked, precision, device, and `encode`,
    a picklable function of a Frame that turns it into what the client needs (for instance a frame's
    files: the encoding then runs on the workers too), or None to return the Frame itself."""

    idempotent = False

    def __init__(self, scene: Scene, aovs=AOVS, precision: str = "fp32", device: str | None = None, encode=None,
                 time=None):
        if device is not None and not isinstance(device, str):
            raise RequestError("device: on a cluster, give a selector string (P:D or a part of its name), "
                               f"not {type(device).__name__}: each worker picks its own device")
        self.name = f"pyclray-{uuid.uuid4().hex[:12]}"
        self.scene, self.aovs, self.precision, self.device, self.encode = scene, aovs, precision, device, encode
        self.time = time  # the animated scene's time its views and windows are at (for flow), or None

    async def setup(self, worker=None):
        # in a thread: building a program takes seconds, and the worker's event loop keeps beating
        await asyncio.get_running_loop().run_in_executor(None, self.warm)

    def warm(self):
        """The OpenCL context and the program, made before the first task (a one-pixel render of the
        scene: the frames, views and bands of a job all use its program); raises what a task would."""
        self._render(self.scene, (0, 0, 1, 1), time=self.time or (0.0 if "flow" in self.aovs and self.scene.animation else None))

    def teardown(self, worker=None):
        self.scene = None

    def _render(self, scene: Scene, window=None, time=None) -> Frame:
        return render(scene, aovs=self.aovs, precision=self.precision, device=self.device, window=window,
                      time=self.time if time is None else time)

    def _out(self, frame: Frame):
        return frame if self.encode is None else self.encode(frame)

    # one method per kind of task; the argument is all that travels with a task
    def frame(self, k: int):
        """Frame k of the scene's animation: exactly render(scene, time=k / fps) (scene.at(k / fps))."""
        return self._out(self._render(self.scene, time=self.scene.animation.frame_time(k)))

    def view(self, view):
        """The scene seen by a camera, or a whole other scene (which travels with its task)."""
        scene = view if isinstance(view, Scene) else dataclasses.replace(self.scene, camera=view)
        return self._out(self._render(scene))

    def window(self, window):
        """The window (x0, y0, width, height) of the scene's image: its pixels in the whole image."""
        return self._out(self._render(self.scene, window))


class Work(WorkerPlugin):
    """A job of any picklable work object (a data set's views: pyclray.io.dataset.DatasetViews): it
    travels once per worker, where work.prepare() builds its scene handles before the first task;
    a task is work(argument); work.close() at the end."""

    idempotent = False

    def __init__(self, work):
        self.name = f"pyclray-{uuid.uuid4().hex[:12]}"
        self.work = work

    async def setup(self, worker=None):
        await asyncio.get_running_loop().run_in_executor(None, self.work.prepare)

    def teardown(self, worker=None):
        self.work.close()

    def call(self, argument):
        return self.work(argument)


def map_work(client: Client, work, arguments, progress=None, what: str = "task"):
    """Yield work(argument) for each argument, in order, from the cluster's workers, each of which
    prepares the work once (Work)."""
    for _, result in run(client, Work(work), "call", arguments, progress, what=what):
        yield result


def _task(job: str, method: str, argument):
    """A task: the job's method on this worker (Job registered under the name `job`)."""
    return getattr(get_worker().plugins[job], method)(argument)


def run(client: Client, job: Job, method: str, arguments, progress=None, what: str = "task"):
    """Yield (i, result of job.<method>(arguments[i])) for every argument, in order, from the
    cluster's workers. progress: something with update(n) (a tqdm bar), advanced as tasks complete.
    On an error, or when the caller stops early, the tasks in flight are cancelled; the job is
    removed from the workers at the end."""
    arguments = list(arguments)
    futures = {}
    try:
        client.register_plugin(job, name=job.name)  # raises here what the job's setup raised on a worker
        threads = sum(client.nthreads().values())
        ahead = max(AHEAD_MIN, AHEAD_PER_THREAD * threads)
        # each result is fetched as its task completes (concurrently, in the client's event loop) and
        # handed over once every earlier one has been; a new task is submitted for each one handed
        # over, so the client holds at most `ahead` results (back-pressure from a slow consumer)
        completed = as_completed(loop=client.loop, with_results=True, raise_errors=False)
        index = {}

        def submit(i):
            if i < len(arguments):
                future = client.submit(_task, job.name, method, arguments[i], key=f"{job.name}-{method}-{i}", pure=False)
                futures[i], index[future.key] = future, i
                completed.add(future)

        for i in range(ahead):
            submit(i)
        arrived, next_i = {}, 0
        for future, result in completed:
            i = index.pop(future.key)
            if future.status != "finished":
                _raise(future, f"{what} {arguments[i]!r}")
            del futures[i]
            future.release()  # the worker may drop its copy
            if progress is not None:
                progress.update(1)
            arrived[i] = result
            while next_i in arrived:
                yield next_i, arrived.pop(next_i)
                submit(next_i + ahead)
                next_i += 1
    finally:
        if futures and client.status == "running":
            client.cancel(list(futures.values()))
        if client.status == "running":
            with suppress(ValueError):  # not registered: the scheduler had refused it
                client.unregister_worker_plugin(job.name)


def _raise(future, what: str):
    """Raise a task's error in the client: the worker's exception itself (a PyclrayError keeps its one
    line), or a PyclrayError for a task that killed every worker that ran it."""
    try:
        future.result()
    except KilledWorker as error:
        raise PyclrayError(f"{what}: the workers that ran it died each time ({error})") from None
    raise PyclrayError(f"{what}: the task was {future.status} on the cluster")


# -- what users call ----------------------------------------------------------------------------
def render_animation(client: Client, scene: Scene, aovs=AOVS, precision: str = "fp32", device=None,
                     frames=None, encode=None, progress=None):
    """As pyclray.render_animation, on the cluster: yield (t, Frame) for the frames (default all),
    in order; frame k is exactly render(scene.at(k / fps)). encode: see Job (then (t, encode(Frame)))."""
    from ..model.errors import SceneError

    animation = scene.animation
    if animation is None:
        raise SceneError("the scene has no [animation] table", file=scene.source)
    frames = list(range(animation.frame_count()) if frames is None else frames)
    job = Job(scene, aovs, precision, device, encode)
    for i, result in run(client, job, "frame", frames, progress, what="frame"):
        yield animation.frame_time(frames[i]), result


def render_views(client: Client, scene: Scene, views, aovs=AOVS, precision: str = "fp32", device=None,
                 encode=None, progress=None):
    """Yield (i, Frame) for each of `views` in order, rendered on the cluster: a Camera renders the
    scene seen by it (only the camera travels with its task), a Scene is rendered as it is (it travels
    with its task). Exactly render(scene with that camera) or render(that scene)."""
    views = list(views)
    for i, view in enumerate(views):
        if not isinstance(view, (Camera, Scene)):
            raise RequestError(f"views: item {i} is a {type(view).__name__}; expected a pyclray Camera or Scene")
    yield from run(client, Job(scene, aovs, precision, device, encode), "view", views, progress, what="view")


def band_rows(width: int, height: int) -> int:
    """Rows of a band task: about TASK_PIXELS pixels, at least one row, at most the image."""
    return max(1, min(height, TASK_PIXELS // width))


def render_bands(client: Client, scene: Scene, aovs=AOVS, precision: str = "fp32", device=None,
                 rows: int | None = None, progress=None, time=None):
    """Yield the scene's image in bands of `rows` whole rows (default band_rows), top to bottom,
    rendered on the cluster's workers: band j is render(scene, window=(0, j * rows, width, rows)),
    the whole image's pixels bit for bit. At most a few bands per worker thread are in flight."""
    width, height = scene.image.width, scene.image.height
    rows = band_rows(width, height) if rows is None else rows
    if not (isinstance(rows, int) and rows >= 1):
        raise RequestError(f"rows: expected a whole number of rows >= 1, got {rows!r}")
    windows = [(0, top, width, min(rows, height - top)) for top in range(0, height, rows)]
    for _, band in run(client, Job(scene, aovs, precision, device, time=time), "window", windows, progress, what="band"):
        yield band


def render_image(client: Client, scene: Scene, aovs=AOVS, precision: str = "fp32", device=None,
                 rows: int | None = None, progress=None) -> Frame:
    """render(scene), with the image's bands (see render_bands) rendered on the cluster's workers:
    the same images, bit for bit."""
    import numpy as np

    from ..engine.queries.memory import check_images_fit
    from ..model.aovs import TABLE

    # the whole image is put together here: it must fit in this machine's memory (a RequestError
    # naming the bytes, before any task runs; render_bands streams it instead). A request of the
    # wrong kind is left to the workers, which say what is wrong with it.
    asked = (aovs.split(",") if isinstance(aovs, str) else list(aovs)) if aovs is not None else []
    if asked and all(isinstance(a, str) and a.strip() in TABLE for a in asked) and precision in ("fp32", "fp64"):
        check_images_fit(tuple(a.strip() for a in asked), precision, scene.image.width, scene.image.height)
    images, devices, top = {}, [], 0
    for band in render_bands(client, scene, aovs, precision, device, rows, progress):
        for name, array in band.items():
            if name not in images:
                images[name] = np.empty((scene.image.height,) + array.shape[1:], array.dtype)
            images[name][top:top + array.shape[0]] = array
        top += next(iter(band.values())).shape[0]
        if band.device not in devices:
            devices.append(band.device)
    return Frame(images, precision=band.precision, device=" + ".join(devices),
                 **frame_camera(scene.camera, scene.image.width, scene.image.height))
