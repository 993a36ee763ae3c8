"""A graph file naming 'château.jpg' typed composed (NFC) beside a file of that name written
decomposed (NFD, as macOS writes file names) was refused with "image 'château.jpg' is not
one of the 3 images (b.jpg, château.jpg, …)": the same text, printed alike. A name now
finds its image in either Unicode form, where no other image shares that form."""

import unicodedata

import pytest

from pipeline.commgraph import read_comm_graph
from pipeline.errors import InputError


def nfc(s):
    return unicodedata.normalize("NFC", s)


def nfd(s):
    return unicodedata.normalize("NFD", s)


@pytest.mark.parametrize(("in_names", "in_file"), [(nfd, nfc), (nfc, nfd)],
                         ids=["files-nfd-graph-nfc", "files-nfc-graph-nfd"])
def test_a_name_finds_its_image_in_either_form(tmp_path, in_names, in_file):
    names = [in_names(n) for n in ("b.jpg", "château.jpg", "église.jpg")]
    assert names[1] != in_file("château.jpg")  # the two encodings differ, byte by byte
    graph = tmp_path / "graph.csv"
    graph.write_text(in_file("château.jpg,église.jpg\nb.jpg,château.jpg\n"), encoding="utf-8")
    assert read_comm_graph(graph, names).tolist() == [[0, 1], [1, 2]]


def test_two_images_whose_names_differ_only_in_form_are_each_found_as_written(tmp_path):
    names = [nfc("é.jpg"), nfd("é.jpg"), "x.jpg"]
    graph = tmp_path / "graph.csv"
    graph.write_text(f"{names[0]},x.jpg\n{names[1]},x.jpg\n", encoding="utf-8")
    assert read_comm_graph(graph, names).tolist() == [[0, 2], [1, 2]]


def test_a_name_of_no_image_is_still_refused(tmp_path):
    graph = tmp_path / "graph.csv"
    graph.write_text("chateau.jpg,b.jpg\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 1: image 'chateau.jpg' is not one of the 2"):
        read_comm_graph(graph, [nfd("château.jpg"), "b.jpg"])
