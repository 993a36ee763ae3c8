"""A Ctrl-C during COLMAP's mapping ends the command even when pycolmap swallows it."""

import os
import signal

import pytest

import pipeline.colmap.mapping as mapping


def test_an_interrupt_swallowed_by_the_mapping_is_raised_after_it(monkeypatch, tmp_path):
    """pycolmap's mapping may catch the KeyboardInterrupt raised in its Python callback (the
    progress bar), keep its reconstruction and return: clean-db --fusion then wrote a result
    after a Ctrl-C. The fake below does exactly that."""
    calls = []

    def swallowing(database_path, image_dir, out, options, input_path="",
                   initial_image_pair_callback=None, next_image_callback=None):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            next_image_callback()  # the handler runs at the latest here
        except KeyboardInterrupt:
            calls.append("swallowed")
        return {}

    monkeypatch.setattr(mapping.pycolmap, "incremental_mapping", swallowing)
    with pytest.raises(KeyboardInterrupt):
        mapping._mapping(tmp_path / "db", str(tmp_path), tmp_path, None, 2)
    assert calls == ["swallowed"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def test_a_mapping_without_interrupt_returns_its_result(monkeypatch, tmp_path):
    monkeypatch.setattr(mapping.pycolmap, "incremental_mapping",
                        lambda *a, **k: {0: "model"})
    assert mapping._mapping(tmp_path / "db", str(tmp_path), tmp_path, None, 2) == {0: "model"}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_sigterm_swallowed_by_the_mapping_is_raised_after_it(monkeypatch, tmp_path, sig):
    """The command line ends on a SIGTERM (or a SIGHUP) through its clean-up (a Python handler
    raising Terminated, pipeline.errors.clean_up_on_terminate); swallowed by the mapping as
    above, the command went on and wrote a result from a cut-short mapping."""
    from pipeline.errors import Terminated, _on_terminate

    calls = []

    def swallowing(database_path, image_dir, out, options, input_path="",
                   initial_image_pair_callback=None, next_image_callback=None):
        try:
            os.kill(os.getpid(), sig)
            next_image_callback()
        except BaseException:  # noqa: BLE001 - what the C++ side does with it
            calls.append("swallowed")
        return {}

    monkeypatch.setattr(mapping.pycolmap, "incremental_mapping", swallowing)
    previous = signal.signal(sig, _on_terminate)
    try:
        with pytest.raises(Terminated) as got:
            mapping._mapping(tmp_path / "db", str(tmp_path), tmp_path, None, 2)
        assert got.value.code == 128 + sig
        assert signal.getsignal(sig) is _on_terminate  # restored
    finally:
        signal.signal(sig, previous)
    assert calls == ["swallowed"]
