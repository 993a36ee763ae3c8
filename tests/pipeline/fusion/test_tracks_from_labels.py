"""Tracks of the fusion stage from the robots' own track names."""


from pipeline.fusion.landmarks import tracks_from_labels


def test_a_name_held_by_one_feature_is_no_track():
    # features 0, 3 share name 5; feature 1 alone holds 2; 2 and 4 hold none; 5, 6 share 9
    track_of, T, names = tracks_from_labels([5, 2, -1, 5, -1, 9, 9], 7)
    assert T == 2
    assert names.tolist() == [5, 9]
    assert track_of.tolist() == [0, -1, -1, 0, -1, 1, 1]
