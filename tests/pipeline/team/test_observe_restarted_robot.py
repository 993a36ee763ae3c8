"""A robot killed mid-run and started again by hand with the same id: the observer reports it
lost, as its neighbours treated it, instead of taking its new process's result for it."""

import threading
import time

from pipeline.team.launcher import make_team
from pipeline.team.observe import observe_team
from pipeline.transport.wire import encode_packet
from pipeline.transport.zenoh_transport import key, open_session


def test_a_robot_restarted_with_the_same_id_is_reported_lost():
    team = make_team("restarted", [[0, 1]], {"kind": "links", "links": "x.csv",
                                             "features_per_camera": [1, 1]}, n=2)
    stop = threading.Event()
    first_gone = threading.Event()  # robot 1's first process ended
    logs = []

    def robot(i, first_process, header):
        if first_process:  # started, then killed before publishing
            s = open_session([team.endpoint(i)], [team.observer], f"robot {i}")
            # the observer hears it only once connected (a loaded machine takes a while)
            t0 = time.monotonic()
            while not list(s.info.peers_zid()) and time.monotonic() - t0 < 30:
                time.sleep(0.01)
            token = s.liveliness().declare_token(key(team.name, "live", i))
            for _ in range(10):  # said again: a put before the observer's subscription reached
                s.put(key(team.name, "status", i), "started")  # this session is lost
                time.sleep(0.1)
            token.undeclare()
            s.close()
            first_gone.set()
            time.sleep(0.5)
        else:  # the survivor wrote robot 1 off once its first process had ended
            first_gone.wait(60)
        s = open_session([team.endpoint(i)], [team.observer], f"robot {i}")
        token = s.liveliness().declare_token(key(team.name, "live", i))
        s.put(key(team.name, "status", i), "started")
        result = encode_packet({"id": i, **header}, [("result", {})])
        try:
            while not stop.wait(0.1):
                s.put(key(team.name, "result", i), result)
        finally:
            token.undeclare()
            s.close()

    survivor = {"counters": {"outcome": "cut", "written_off": {"1": "closed"}}}
    told = {"counters": {"outcome": "partitioned", "written_off": {"0": "told"}}}
    threads = [threading.Thread(target=robot, args=(0, False, survivor)),
               threading.Thread(target=robot, args=(1, True, told))]
    for t in threads:
        t.start()
    try:
        run = observe_team(team, timeout_s=60, log=logs.append)
    finally:
        stop.set()
        for t in threads:
            t.join()
    assert sorted(run.results) == [0]
    assert sorted(run.killed) == [1]
    assert any(line.startswith("robot 1 (tcp/127.0.0.1:") and "was started again after its "
               "process had ended without a result" in line for line in logs), logs
