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


def test_script_help_speaks_of_options_not_of_the_panel():
    """bake_ao.py --help names other settings by their options (--min-samples, not "Min Samples") and
    their choices by the option's words (--images atlas, not "One for All"), and says nothing a script
    cannot do (shift-click) or set (32-bit Float, Save to File)."""
    import re

    from mc_ao import schema
    from mc_ao.cli.options import make_parser, script_help

    labels = {s.label for s in schema.SETTINGS}
    choices = {item[1] for s in schema.SETTINGS for item in s.items if " " in item[1]}  # "One for All"
    for setting in schema.SETTINGS:
        if setting.option is None:
            continue
        text = script_help(setting)
        named = [label for label in labels if label != setting.label
                 and re.search(rf"(?<![.] )(?<!^)(?<![\w-]){re.escape(label)}\b", text)]
        assert named == [], f"{setting.option}: {named} in {text!r}"
        others = [name for name in choices - {item[1] for item in setting.items} if name in text]
        assert others == [], f"{setting.option}: the panel's choices {others} in {text!r}"
        assert "click" not in text.lower() and "panel" not in text.lower(), text
    shown = " ".join(make_parser(with_blend=True).format_help().split())
    assert "Min Samples" not in shown and "shift-click" not in shown and "Ground is Height" not in shown
    assert "stop at --min-samples" in shown and "(--quantity ao thickness)" in shown


def test_the_batch_counts_an_object_with_two_quantities_once():
    """A task's summary lists AO and thickness of one object as two entries: the batch's line and
    table say one object."""
    from mc_ao_batch.report import object_count

    record = {"objects": [{"object": "Suzanne", "files": ["Suzanne_AO.png"]},
                          {"object": "Suzanne", "files": ["Suzanne_Thickness.png"]},
                          {"object": "Ground", "files": ["Ground_AO.png"]}]}
    assert object_count(record) == 2
