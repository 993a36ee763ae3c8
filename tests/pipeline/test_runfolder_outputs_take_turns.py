"""Two commands putting outputs of the same names in place at once (clean-db --overwrite into
one OUT.db, twice) take turns: the outputs left are one command's, never one's OUT.db beside
the other's OUT.links.csv."""

import threading
import time

import pipeline.runfolder as runfolder
from pipeline.runfolder import OutputFiles


def test_two_commands_replacing_the_same_outputs_do_not_mix_them(tmp_path, monkeypatch):
    db, links = tmp_path / "out.db", tmp_path / "out.links.csv"
    first_out = threading.Event()
    publish = runfolder.publish

    def slow_publish(tmp, path, replace):
        publish(tmp, path, replace)
        if threading.current_thread().name == "A" and path == db:
            first_out.set()  # A has put OUT.db in place, not yet OUT.links.csv
            time.sleep(0.5)

    monkeypatch.setattr(runfolder, "publish", slow_publish)

    def command(name):
        if name == "B":
            first_out.wait(5)
        with OutputFiles(replace=True) as out:
            out.path(db, "--out").write_text(name)
            out.path(links, "--out").write_text(name)

    threads = [threading.Thread(target=command, args=(n,), name=n) for n in "AB"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert db.read_text() == links.read_text() == "B"  # B's, put in place after A's
