"""The models added by YAML alone, on real images: a YOLOv8 fall detector and PP-OCR's
text-direction classifier, each through the same declared pre- and post-processing."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from oricf.config import REPO_ROOT
from oricf.models.declaration import load_declaration
from oricf.models.declared import DeclaredModel
from oricf.models.heads import ClassificationHead, DetectionHead
from oricf.store import ModelStore
from tests.support.data import image, text_crops

MODELS = REPO_ROOT / "configs" / "models"


def loaded(name: str) -> Iterator[DeclaredModel]:
    model = DeclaredModel(load_declaration(MODELS / f"{name}.yaml"), ModelStore())
    model.load()
    yield model
    model.close()


@pytest.fixture(scope="module")
def fall() -> Iterator[DeclaredModel]:
    yield from loaded("yolov8-fall")


@pytest.fixture(scope="module")
def direction() -> Iterator[DeclaredModel]:
    yield from loaded("text-direction")


def labels_found(model: DeclaredModel, pixels: np.ndarray) -> list[str]:
    assert isinstance(model.head, DetectionHead)
    found = model.detect(model.prepare(pixels), model.head.task.min_score)
    return sorted(model.head.labels[c] for c in found.class_ids)


def test_fall_detector_sees_a_standing_person_and_no_animals(fall: DeclaredModel) -> None:
    assert labels_found(fall, cv2.imread(str(image("person.jpg")))) == ["normal"]
    assert labels_found(fall, cv2.imread(str(image("dog.jpg")))) == []
    assert labels_found(fall, cv2.imread(str(image("horses.jpg")))) == []


def test_fall_detector_sees_a_person_lying_down_as_fallen(fall: DeclaredModel) -> None:
    lying = cv2.rotate(cv2.imread(str(image("person.jpg"))), cv2.ROTATE_90_CLOCKWISE)
    found = labels_found(fall, lying)
    assert "fall" in found and "normal" not in found


def test_fall_detector_boxes_are_in_image_pixels(fall: DeclaredModel) -> None:
    photo = cv2.imread(str(image("person.jpg")))  # 640x424: the person stands left of centre
    found = fall.detect(fall.prepare(photo), 0.4)
    x_min, y_min, x_max, y_max = found.boxes[0]
    assert 0 <= x_min < x_max <= photo.shape[1] and 0 <= y_min < y_max <= photo.shape[0]
    assert x_max - x_min < photo.shape[1] / 2 and y_max - y_min > photo.shape[0] / 2


def test_text_direction_tells_upright_from_upside_down(direction: DeclaredModel) -> None:
    head = direction.head
    assert isinstance(head, ClassificationHead)
    right, total = 0, 0
    for crop in text_crops():
        for want, pixels in (("0", crop), ("180", cv2.rotate(crop, cv2.ROTATE_180))):
            prepared = head.prepare(pixels)
            classes = head.decode(direction.infer(prepared.feeds), prepared)
            right += classes.labels[0] == want
            total += 1
    assert total >= 100 and right / total >= 0.85, (right, total)


def test_the_classifier_has_free_input_dimensions_from_its_file(
        direction: DeclaredModel) -> None:
    assert [(s.name, s.shape) for s in direction.inputs] == [("x", (-1, 3, -1, -1))]
    assert direction.outputs[0].shape == (-1, 2)
