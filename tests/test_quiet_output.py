"""What the commands print is what the user needs: no log lines of the libraries underneath."""

import importlib.util
import socket
import warnings

import pytest


@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="needs distributed (requirements-batch.txt)")
def test_local_dask_cluster_is_quiet_beside_another_cluster():
    """The batch's LocalCluster while another program holds Dask's dashboard port (8787, another
    cluster on the machine): no "Port 8787 is already in use" UserWarning in the batch's output."""
    from mc_ao_batch.runners import start_local_cluster

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))
        holder.listen()
    except OSError:
        pass  # another cluster holds it already: the case itself
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cluster = start_local_cluster(1)
            cluster.close()
        assert [str(w.message) for w in caught if "already in use" in str(w.message)] == []
    finally:
        holder.close()
