"""Device choice and the ``torch.distributed`` helpers of the training loop (private).

Launched with ``torchrun`` (env vars ``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``, ``MASTER_ADDR``,
``MASTER_PORT``), the loop initialises a process group (backend ``gloo`` on CPU, ``nccl`` on CUDA);
with one process every helper here is a no-op.

Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import os

import torch


def _resolve_device(device: str | torch.device, local_rank: int = 0) -> torch.device:
    if isinstance(device, torch.device):
        return device
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("device 'cuda' requested but torch.cuda.is_available() is False")
        return torch.device("cuda", local_rank)
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"device must be 'auto', 'cpu', 'cuda', 'cuda:N' or 'mps', got "
                         f"{device!r}") from None
    # a device this machine lacks: said now, not as a failure to load or move weights later
    if dev.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if (dev.index or 0) >= count:
            raise ValueError(f"device {device!r}: this machine has {count} CUDA device(s) "
                             "(torch.cuda.is_available() says so); use --device cpu or auto")
    elif dev.type == "mps":
        mps = getattr(torch.backends, "mps", None)
        if mps is None or not mps.is_available():
            raise ValueError(f"device {device!r}: this machine has no MPS (Apple GPU) device "
                             "(torch.backends.mps.is_available() is False); use --device cpu "
                             "or auto")
    elif dev.type != "cpu":
        raise ValueError(f"device must be 'auto', 'cpu', 'cuda', 'cuda:N' or 'mps', got "
                         f"{device!r}")
    return dev


def _init_distributed(device: torch.device) -> tuple[int, int, bool]:
    """``(rank, world_size, initialised_here)``; initialises from torchrun's env vars."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size(), False
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, False
    if not dist.is_available():
        raise RuntimeError("WORLD_SIZE > 1 but torch.distributed is not available")
    backend = "nccl" if device.type == "cuda" else "gloo"
    dist.init_process_group(backend=backend, init_method="env://")
    return dist.get_rank(), dist.get_world_size(), True


def _barrier(world: int) -> None:
    if world > 1:
        import torch.distributed as dist

        dist.barrier()


def _mean_over_ranks(value: float, world: int, device: torch.device) -> float:
    if world == 1:
        return value
    import torch.distributed as dist

    t = torch.tensor([value], dtype=torch.float64, device=device)
    dist.all_reduce(t)
    return float(t.item()) / world


def _broadcast_row(row: dict, world: int) -> dict:
    """Rank 0's validation numbers to every rank (so callbacks and results agree)."""
    if world == 1:
        return row
    import torch.distributed as dist

    obj = [row]
    dist.broadcast_object_list(obj, src=0)
    return obj[0]
