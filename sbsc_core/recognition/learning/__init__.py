"""Learning from reviewed objects: new classes and new designs of a model library (``sbsc learn``).

- :mod:`.crops`: an object's crops out of a surface's orthoimages, and their medians;
- :mod:`.snap`: an object placed where a depth model matches the relief nearby;
- :mod:`.examples`: reviewed objects found on the surfaces of a detect output;
- :mod:`.library`: the learnt library (:func:`learn_library`);
- :mod:`.forget`: a library without what was learnt for a class (the review app's remove and re-teach);
- :mod:`.command`: the ``sbsc learn`` command.
"""
