"""Create an object: validated completely before an id is taken, stored with its `object_created` event in one
write."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.event_log import EventKind, ObjectCreatedData
from planhrc.geometry import GeometryError, ObjectGeometry
from planhrc.model import make_object

from ..store import ValidationError
from .context import Context
from .log import log_event
from .reads import read_object
from .unit_of_work import object_write
from .values import ObjectRead


@dataclass(frozen=True)
class NewObject:
    """An object to create: `links` a count (each link of the default length) or the links' lengths in metres;
    with `base_point_xy` ([x, y] metres) it is placed in the cell and its goals and plans are checked
    geometrically."""

    name: str
    links: int | tuple[float, ...]
    orientations: int
    formulation: str
    base_point_xy: tuple[float, ...] | None = None


def create_object(context: Context, request: NewObject) -> ObjectRead:
    """Create the object (its base point, if any, kept in its `object_created` event, which the log keeps whole).
    Its planning task (links x orientations) is bounded by the setting `max_task_size`."""
    store, settings = context.store, context.settings
    probe = make_object("probe", request.formulation, request.links, request.orientations, request.name)
    size = probe.n_links * probe.orientations
    if size > settings.max_task_size:
        raise ValidationError(
            f"links, orientations: {probe.n_links} links x {probe.orientations} orientations = {size} is over "
            f"the largest planning task this service takes ({settings.max_task_size}, PLANHRC_MAX_TASK_SIZE)")
    base = None
    if request.base_point_xy is not None:
        xy = request.base_point_xy
        try:
            base = ObjectGeometry.of(probe, (xy[0], xy[1])).base_point_xy
        except (GeometryError, IndexError, TypeError) as exc:
            raise ValidationError(f"base_point_xy: expected [x, y] in metres ({exc})") from None
    object_id = store.new_object_id()
    obj = make_object(object_id, request.formulation, request.links, request.orientations, request.name)
    with context.locks.hold(object_id), object_write(context, object_id):
        store.create_object(obj)
        log_event(store, object_id, EventKind.OBJECT_CREATED, f"object {object_id} created",
                  ObjectCreatedData(formulation=obj.formulation, links=obj.n_links,
                                    orientations=obj.orientations, base_point_xy=base))
    return read_object(context, object_id)
