"""Alg. 1 cases (a)-(d) at one receiving robot, including requests that arrive together."""

import numpy as np

from pipeline.consistency.resolution import resolution_step
from pipeline.consistency.robot import Robot
from pipeline.transport import Message

# robot 0 has 3 features; robots 1 and 2 have 3 each; links (0,r)-(1,r) and (0,r)-(2,r)
FPC = [3, 3, 3]


def receiver():
    return Robot(0, FPC, [1, 1, 1, 2, 2, 2], [0, 1, 2, 0, 1, 2], [0, 1, 2, 0, 1, 2])


def request(src, q, src_feat, dst_feat):
    return Message(src, 0, "request", {"q": np.array(q, np.int32),
                                       "src_feat": np.array(src_feat, np.int32),
                                       "dst_feat": np.array(dst_feat, np.int32)})


def run(rb, inbox):
    sent = []
    resolution_step(rb, inbox, lambda dst, kind, p: sent.append((dst, kind, p)), 1)
    return sent


def test_two_components_ask_for_one_feature_lowest_component_wins():
    rb = receiver()
    # C_6 (from robot 2) and C_3 (from robot 1) both reach feature 0 in the same round
    sent = run(rb, [request(2, [6], [0], [0]), request(1, [3], [0], [0])])
    assert rb.component[0] == 3  # order (component id, sender robot, sender feature)
    assert not rb.link_alive[3] and rb.deleted_case[3] == 1  # link to robot 2 cut, case (b)
    rejects = [(d, p["src_feat"].tolist(), p["dst_feat"].tolist()) for d, k, p in sent if k == "reject"]
    assert rejects == [(2, [0], [0])]
    # the new member forwards C_3 along its remaining links only (none left here)
    assert [k for _, k, _ in sent] == ["reject"]


def test_one_component_asks_for_two_features_case_c():
    rb = receiver()
    run(rb, [request(1, [3], [1], [1]), request(2, [3], [2], [2])])
    assert rb.component.tolist() == [-1, 3, -1]  # sender robot 1 first
    assert not rb.link_alive[5] and rb.deleted_case[5] == 2  # (c)
    assert rb.link_alive[:5].all()


def test_case_a_keeps_the_link_and_case_d_forwards():
    rb = receiver()
    sent = run(rb, [request(1, [3], [0], [0])])
    assert rb.component[0] == 3
    fwd = [(d, p["q"].tolist(), p["src_feat"].tolist()) for d, k, p in sent if k == "request"]
    assert fwd == [(2, [3], [0])]  # (d): forwarded to robot 2, not back to robot 1
    sent = run(rb, [request(2, [3], [0], [0])])  # C_3 comes back over the other link
    assert sent == [] and rb.link_alive.all()  # (a)


def test_reject_deletes_the_senders_side():
    rb = receiver()
    rb.component[1] = 4
    resolution_step(rb, [Message(2, 0, "reject", {"src_feat": np.array([1], np.int32),
                                                   "dst_feat": np.array([1], np.int32)})],
                    lambda *a: None, 2)
    assert not rb.link_alive[4] and rb.deleted_round[4] == 2 and rb.deleted_case[4] == 3


def rejects_of(sent):
    return [(d, p["src_feat"].tolist(), p["dst_feat"].tolist()) for d, k, p in sent if k == "reject"]


def test_the_lower_component_wins_whichever_robot_sends_it():
    rb = receiver()
    # C_3 now comes from robot 2 and C_6 from robot 1: the order is by component first
    sent = run(rb, [request(1, [6], [0], [0]), request(2, [3], [0], [0])])
    assert rb.component[0] == 3
    assert not rb.link_alive[0] and rb.deleted_case[0] == 1  # link to robot 1 cut, case (b)
    assert rb.link_alive[3]
    assert rejects_of(sent) == [(1, [0], [0])]


def test_one_component_reaching_a_feature_over_two_links_keeps_both():
    rb = receiver()
    # C_5 reaches feature 0 from robots 1 and 2 in one round: (d) for the first, (a) for the
    # second, nothing cut, nothing forwarded (both links settled this round)
    sent = run(rb, [request(1, [5], [0], [0]), request(2, [5], [0], [0])])
    assert rb.component.tolist() == [5, -1, -1]
    assert rb.link_alive.all()
    assert sent == []


def test_a_feature_in_component_zero_rejects_another_component():
    rb = receiver()
    rb.component[0] = 0  # C_0: the component of the root feature with global id 0
    sent = run(rb, [request(1, [3], [0], [0])])
    assert rb.component[0] == 0
    assert not rb.link_alive[0] and rb.deleted_case[0] == 1  # (b)
    assert rejects_of(sent) == [(1, [0], [0])]


def test_case_c_replies_a_reject():
    rb = receiver()
    sent = run(rb, [request(1, [3], [1], [1]), request(2, [3], [2], [2])])
    assert rejects_of(sent) == [(2, [2], [2])]  # the sender drops its side too (line 11)
