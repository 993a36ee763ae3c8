"""Online association (pipeline.consistency.engines.online): a step whose stage loses robots
(``OnlineAssociation._stage_despite_losses``). A robot lost once is started again and the step
decides as without the loss; an image lost twice has its links of the step's sub-problem cut
``robot-lost``; the association stays conflict-free after every step either way."""

import pytest
from hypothesis import HealthCheck, given, settings
from online_streams import streams

from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.online import Frame, OnlineAssociation, simulated_stage
from pipeline.errors import RobotsLost
from pipeline.types import Links


class LossyStage:
    """The simulator's stage, losing camera ``camera`` of the sub-problem on the calls of
    ``losing`` (numbered from 0), with what the lost attempt spent."""

    def __init__(self, losing, camera=0):
        self.losing, self.camera, self.calls = set(losing), camera, 0

    def __call__(self, fpc, links, resolution, **kw):
        k, self.calls = self.calls, self.calls + 1
        if k in self.losing:
            raise RobotsLost("lost", [min(self.camera, len(fpc) - 1)],
                             dict(messages=3, bytes=70, rounds=2))
        return simulated_stage(fpc, links, resolution, **kw)


def _ledger(oa):
    L = oa.links
    return L.kept.tolist(), L.reason.tolist(), L.step_cut.tolist()


@pytest.mark.parametrize("resolution", ["paper", "evidence"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams())
def test_a_robot_lost_once_is_started_again_and_the_step_decides_alike(resolution, data):
    window, hold, stream = data
    ref = OnlineAssociation(window, resolution=resolution, hold=hold)
    stage = LossyStage(losing=range(0, 1000, 2))  # every step's first attempt loses a robot
    oa = OnlineAssociation(window, resolution=resolution, hold=hold, stage=stage)
    for frames, links in stream:
        want = ref.add_step(frames, links)
        images = oa.n_images
        rec = oa.add_step(frames, links)
        assert _ledger(oa) == _ledger(ref)
        if want["links_new"]:
            assert rec["stage_attempts"] == 2 and rec["cut_lost"] == 0
            assert len(rec["images_lost"]) == 1 and len(rec["images_lost"][0]) == 1
            assert 0 <= rec["images_lost"][0][0] < images + len(frames)
            assert (rec["lost_messages"], rec["lost_bytes"], rec["lost_rounds"]) == (3, 70, 2)
            assert rec["messages"] == want["messages"] + 3
            assert rec["bytes"] == want["bytes"] + 70
            assert rec["rounds"] == want["rounds"] + 2
        else:
            assert rec["stage_attempts"] == 0 and rec["images_lost"] == []
        same = {k: v for k, v in rec.items() if not k.startswith(("lost_", "stage_att"))
                and k not in ("images_lost", "messages", "bytes", "rounds", "wall_s")}
        assert same == {k: want[k] for k in same}


@pytest.mark.parametrize("resolution", ["paper", "evidence"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams())
def test_an_image_lost_twice_has_its_links_of_the_step_cut(resolution, data):
    window, hold, stream = data
    stage = LossyStage(losing={0, 1})  # the first step with links loses one image twice
    oa = OnlineAssociation(window, resolution=resolution, hold=hold, stage=stage)
    lost_at = None
    for frames, links in stream:
        first = oa.n_images
        rec = oa.add_step(frames, links)
        assert is_conflict_free(oa.m, oa.kept_links()), rec
        assert rec["cut"] == rec["cut_rule"] + rec["cut_weigh"] + rec["cut_history"] + \
            rec["cut_lost"]
        if rec["images_lost"] and lost_at is None:
            lost_at = oa.t
            assert rec["images_lost"][0] == rec["images_lost"][1]
            g = rec["images_lost"][0][0]
            L = oa.links
            touching = (L.ci == g) | (L.cj == g)
            new = L.step_added == oa.t
            # every new link of the lost image is cut as robot-lost at this step ...
            assert (~L.kept[touching & new]).all()
            assert set(L.reason[touching & new]) <= {"robot-lost"}
            lost = L.reason == "robot-lost"
            assert rec["cut_lost"] == int(lost.sum()) == int((touching & new).sum()) + int(
                (lost & ~new).sum())
            # ... and nothing else is: only its links, all cut at this step
            assert touching[lost].all() and (L.step_cut[lost] == oa.t).all()
            # the rest of the step is decided by the stage run without them
            assert rec["stage_attempts"] == (3 if (new & ~touching).any() else 2)
            assert 0 <= g < first + len(frames)
    assert stage.calls >= (2 if lost_at is not None else 0)


def test_a_stage_that_always_loses_cuts_its_way_to_an_end():
    """Every attempt loses the sub-problem's first camera: each is started again once, then
    its links are cut, until no new link is left; the step ends conflict-free (it cannot
    loop: each second loss cuts at least one link)."""
    oa = OnlineAssociation(window=2, resolution="paper", stage=LossyStage(range(10**6)))
    oa.add_step([Frame(0, 2), Frame(1, 2), Frame(2, 2)], Links(
        [0, 0, 1, 0], [0, 1, 0, 0], [1, 2, 2, 2], [0, 0, 0, 1]))
    rec = oa.steps[-1]
    assert not oa.links.kept.any() and set(oa.links.reason) == {"robot-lost"}
    assert rec["cut_lost"] == rec["cut"] == 4
    flat = [g for att in rec["images_lost"] for g in att]
    assert all(flat.count(g) == 2 for g in set(flat))  # each image lost twice, then cut
    assert is_conflict_free(oa.m, oa.kept_links())


def test_an_image_lost_again_with_no_link_left_stops_the_step():
    """An image still in the step's sub-problem with none of its links left to cut (over a
    middleware: one that takes part through its border links into retired pieces only) cannot
    be cut out of the step: lost again, the step stops with RobotsLost naming it. Here image
    0 stays in the sub-problem after its links are cut, through the label its feature shares
    with image 1's, which a new link still touches."""

    class LoseImage:
        def __init__(self, oa, image):
            self.oa, self.image = oa, image

        def __call__(self, fpc, links, resolution, **kw):
            images = self.oa._stage_images.tolist()
            if self.image in images:
                raise RobotsLost("lost", [images.index(self.image)])
            return simulated_stage(fpc, links, resolution, **kw)

    oa = OnlineAssociation(window=2, resolution="paper")
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [1], [0]))
    oa.stage = LoseImage(oa, image=0)
    with pytest.raises(RobotsLost) as caught:
        oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 0], [2, 3], [0, 0]))
    # named by its global id alone (the stage's own message names it by its place in the
    # step's sub-problem, another number)
    assert str(caught.value) == (
        "the robot process of image 0 was lost twice during step 1's consistency stage, with "
        "none of its links left in the step's sub-problem to cut (it takes part through "
        "retired pieces only)")
    # its links were cut before the step stopped: the association is still conflict-free
    L = oa.links
    assert L.reason[~L.kept].tolist() == ["robot-lost", "robot-lost"]
    assert is_conflict_free(oa.m, oa.kept_links())
