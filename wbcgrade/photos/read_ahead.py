"""A photo decoded (and prepared for scene matching) on another thread, ahead of its grade.

``apply`` starts one as soon as its options are checked: the decoder and OpenCV's
keypoints hold no interpreter lock for most of their time, so on a second core they run
while the command imports the grade, loads the styles and reads their scene images
(one core of Python). :meth:`ReadAhead.result` waits for the photo and raises what
reading it raised, where the grade would have read it.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.io.images import Image, read_image
from wbcgrade.color.look.scene import (
    forget_photo_scene,
    photo_scene_entry,
    prepare_photo_scene,
)

__all__ = ["ReadAhead", "read_encoded"]


def read_encoded(photo: str | os.PathLike, input_space: str | None,
                 working_space: str | None) -> tuple[Image, ColorEncoding, tuple]:
    """``photo`` read, with its encoding into ``working_space`` from ``input_space`` (None:
    what the file says) and ``encoding.encode`` of its colours: what a grade reads."""
    image = read_image(photo)
    encoding = ColorEncoding.for_image(image, input_space, working_space)
    return image, encoding, encoding.encode(image.rgb(), image.is_float)


class ReadAhead:
    """``photo`` read in a daemon thread, then encoded into ``working_space`` from
    ``input_space`` (None: what the file says; as the grade encodes it) and, with
    ``match_scenes``, prepared for scene matching
    (:func:`wbcgrade.color.look.scene.prepare_photo_scene`). A command that fails
    meanwhile exits once it is done (a thread inside OpenImageIO or OpenCV when the
    interpreter ends aborts the process: these threads are not daemons)."""

    def __init__(self, photo: str | os.PathLike, input_space: str | None = None,
                 working_space: str | None = None, match_scenes: bool = False) -> None:
        self.photo = Path(photo)
        self.spaces = (input_space, working_space)
        self.match_scenes = match_scenes
        #: whether the photo's scene image was started (the grade then forgets it after)
        self.scene_started = False
        self._done = threading.Event()
        self._decided = threading.Event()  # set by proceed() or cancel()
        self._cancelled = threading.Event()
        self._result: tuple[Image, ColorEncoding, tuple] | None = None
        self._error: BaseException | None = None
        threading.Thread(target=self._read, name="wbcgrade-read").start()

    def _read(self) -> None:
        try:
            image, encoding, encoded = read_encoded(self.photo, *self.spaces)
            if self.match_scenes:
                self._decided.wait()  # (the command's outputs planned, or the grade asks)
                if not self._cancelled.is_set():
                    prepare_photo_scene(encoded[0], photo_scene_entry(
                        self.photo, self.spaces[0], encoding.working))
                    self.scene_started = True
            self._result = (image, encoding, encoded)
        except BaseException as exc:  # noqa: BLE001 - raised again where the photo is read
            self._error = exc
        finally:
            self._done.set()

    @classmethod
    def for_grade(cls, photo: str | os.PathLike, source, options) -> ReadAhead:
        """The read-ahead of ``photo`` graded with ``options`` (GradeOptions) towards
        ``source`` (a StyleSource): encoded as the grade will, and prepared for matching
        when the grade will look for its scene among style photos (a look grade, no fixed
        weights, of a folder's photos)."""
        spaces = options.spaces
        return cls(photo, spaces.input, spaces.working,
                   match_scenes=(getattr(source, "style_dir", None) is not None
                                 and options.map.builder == "look"
                                 and options.fit.weights is None))

    def serves(self, photo: str | os.PathLike, input_space: str | None,
               working_space: str | None) -> bool:
        """Whether this is ``photo`` read and encoded as the grade asks for it."""
        if (input_space, working_space) != self.spaces:
            return False
        try:
            return Path(photo) == self.photo or os.path.samefile(photo, self.photo)
        except OSError:
            return False

    def proceed(self) -> None:
        """The grade goes ahead (its outputs are planned): the photo's keypoints may be
        found once it is decoded (they wait for this, so that a command refused by its
        plan exits once the decoder is done)."""
        self._decided.set()

    def cancel(self) -> None:
        """Nothing more than the decode already under way (the command failed: it exits
        once the decoder is done, without finding the photo's keypoints)."""
        self._cancelled.set()
        self._decided.set()

    def discard(self) -> None:
        """Not needed after all (the grade reads the photo otherwise): nothing more started,
        and nothing it prepared kept."""
        self.cancel()
        self._done.wait()
        if self.scene_started and self._result is not None:
            forget_photo_scene(self._result[2][0])

    def result(self) -> tuple[Image, ColorEncoding, tuple[np.ndarray, object]]:
        """(image, encoding, ``encoding.encode`` of its colours), once read; raises what
        reading or encoding it raised."""
        self.proceed()
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._result
