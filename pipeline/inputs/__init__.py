"""Inputs: the files a user hands the pipeline, read and checked at the edge.

Photograph folders and their intrinsics (:mod:`.photos`), links files (:mod:`.linkscsv`, the
``links.csv`` of the run-output contract), hloc's ``features.h5`` / ``matches.h5`` and pair
lists (:mod:`.hloc`), labelled-landmark folders (:mod:`.landmarks`), the fields of a graph
file's line (:mod:`.csvfields`), a COLMAP database's tables checked before pycolmap reads them
(:mod:`.dbcheck`), sparse ids of a links file renumbered (:mod:`.compact`) and ``.npz``
archives read whole without pickles (:mod:`.npzfile`).

May import: the shared words of the root (:mod:`pipeline.errors`, :mod:`pipeline.types`,
:mod:`pipeline.validate`, :mod:`pipeline.outputs`, :mod:`pipeline.runfolder`,
:mod:`pipeline.progress`) and nothing else of the pipeline.
"""
