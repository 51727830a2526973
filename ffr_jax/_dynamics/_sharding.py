"""Batches of designs split across devices (`jax.sharding`)."""

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from ._xla_flags import warn_if_unguarded


def sharded_map(f, devices=None, axis_name: str = "batch", batch_size: int | None = None):
    """`f` over a batch of designs, the batch split evenly across `devices` (`jax.shard_map`).

    Each device evaluates `jax.lax.map(f, ..., batch_size=batch_size)` on its contiguous slice of
    the batch: one entry after another by default, or `jax.vmap` over chunks of `batch_size`
    entries (the better choice on a GPU). Results are
    gathered in batch order, so `sharded_map(f)(xs)[b] == f(xs[b])` for every `b`. A batch
    whose size is not a multiple of the device count is padded with copies of its first entry
    and the padding is dropped from the result. Works for any `f` of one design (a pytree of
    arrays, batched along a leading axis) that `jax.vmap` accepts, including `ffr_jax.value_and_grad`,
    `case.frequencies` and `case.body_data` on either FE path (the sparse path's host callbacks
    run on each device's own slice).

    On CPU, several host devices are made with
    `XLA_FLAGS=--xla_force_host_platform_device_count=N`, set before JAX is imported. Keep
    `batch_size=None` there: batched LAPACK kernels (e.g. a vmapped dense eigen-solution) fan out
    into the thread pool the devices run on and can deadlock it (seen with jaxlib 0.10 on 2 cores);
    a `batch_size` on CPU without `XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false`
    warns so.

    **Arguments:**
    - `f`: function of one batch entry (a pytree of arrays), returning a pytree of arrays.
    - `devices`: sequence of devices (default `jax.devices()`).
    - `axis_name`: name of the mesh axis the batch is split over.
    - `batch_size`: entries evaluated together (vmapped) on each device; `None`: one at a time.

    **Returns:** a compiled function `g(xs)` of a pytree with a leading batch axis.

    **Example:**
    ```python
    import ffr_jax as fj
    case = fj.cases.slider_crank(40, 4, 4, t1=0.2)
    xs = jnp.stack([case.initial_design(v) for v in (0.4, 0.5, 0.6, 0.7)])
    psi, grad = fj.sharded_map(lambda x: fj.value_and_grad(case, x))(xs)
    ```
    """
    if batch_size is not None:
        warn_if_unguarded("sharded_map(batch_size=...)")
    devices = list(jax.devices() if devices is None else devices)
    mesh = Mesh(np.asarray(devices), (axis_name,))
    spec = PartitionSpec(axis_name)
    # check_vma=False: equinox error checks (`eqx.error_if`) branch on replicated and per-device
    # values alike, which the varying-manual-axes type check rejects.
    def local(xs):
        return jax.lax.map(f, xs, batch_size=batch_size)

    mapped = jax.jit(jax.shard_map(local, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False))

    def g(xs):
        sizes = {leaf.shape[0] for leaf in jax.tree.leaves(xs)}
        if len(sizes) != 1:
            raise ValueError(f"sharded_map: every input leaf needs the same leading batch size, got {sorted(sizes)}.")
        (size,) = sizes
        pad = -size % len(devices)
        if pad:
            xs = jax.tree.map(lambda a: jnp.concatenate([a, jnp.repeat(a[:1], pad, axis=0)]), xs)
        out = mapped(xs)
        return jax.tree.map(lambda a: a[:size], out) if pad else out

    return g
