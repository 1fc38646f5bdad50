"""Value fields: every number a page asks for is typed into a `ValueField`, read by the parser of
its kind (station.values), the one the command line uses for the same value (issue 31, part 5).

Why not Textual's `Input(type="number")`: it filters the characters typed, so `1,5` showed `15`
and moved leg 1 to +15 mm. A `ValueField` is a plain Input (every character typed stays, in its
order) whose validator is the kind's parser: a string the command line would refuse is refused
here with the same one-line message, the field is marked invalid (red), and the page shows the
message next to the field. Nothing acts on a refused field: `read()` raises the InputError.

A blank field means the field's default (the option left out on the command line), when the
field has one; blanks around a value are stripped, as the kind's parser does.

FIELD_KINDS names the kind of every value field of every page, for the tests (the UI property
test types generated strings into each and compares what is acted on with `kind.parse`) and for
the command line's options of the same values.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from textual.validation import ValidationResult, Validator
from textual.widgets import Input

from procedures.vocabulary import InputError
from station import values
from station.values import Kind

_REQUIRED = object()  # no default: a blank field is refused


def _cli_kind(name: str, fallback: Kind) -> Kind:
    """The kind the command line uses for a value, by its name in station.values (CYCLES,
    TARGET_COUNT, POSES, REPLAY_SPEED come with the command line's conversion to the kinds, issue
    31 part 1); `fallback`, the general kind of that value, until they are there."""
    return getattr(values, name, fallback)


# Platform poses: at most a million here (a few hundred MB through the experiment; 1e8 grew to
# 24 GB, issue 31), whatever the command line's kind allows: the page runs the experiment in this
# process. A larger count is refused under the field, as one the command line refuses.
POSES_UI = replace(_cli_kind("POSES", values.COUNT), name="a number of poses").bounded(1, 1_000_000)

# field id -> (its kind, the CLI option of the same value). The Rig page's target is narrowed to
# the selected leg's soft limits once they are read (RigScreen), so its kind is the widest one.
FIELD_KINDS: dict[str, tuple[Kind, str]] = {
    "move-target": (values.POSITION_MM, "a position, as station sweep --min-mm/--max-mm (no CLI option moves a leg)"),
    "move-speed": (values.SPEED_MM_S, "a speed in mm/s (no CLI option moves a leg)"),
    "cycles": (_cli_kind("CYCLES", values.COUNT), "station sweep --cycles"),
    "n-targets": (_cli_kind("TARGET_COUNT", values.COUNT), "station sweep --n-targets"),
    "step": (values.STEP_MM, "station sweep --step"),
    "min-mm": (values.POSITION_MM, "station sweep --min-mm"),
    "max-mm": (values.POSITION_MM, "station sweep --max-mm"),
    "dwell": (values.TIME_S, "station sweep --dwell"),
    "comp-step": (values.STEP_MM, "station table --step"),
    "replay-speed": (_cli_kind("REPLAY_SPEED", values.SPEED_FACTOR), "station replay --speed"),
    "plat-poses": (POSES_UI, "station platform --poses (at most a million here)"),
    "plat-seed": (values.SEED, "station platform --seed"),
}


class KindValidator(Validator):
    """The field's own reading as a Textual validator: the refusal is the parser's message."""

    def __init__(self, field: "ValueField") -> None:
        super().__init__()
        self.field = field

    def validate(self, value: str) -> ValidationResult:
        try:
            self.field.read(value)
        except InputError as exc:
            return self.failure(str(exc), value)
        return self.success()


class ValueField(Input):
    """A text field for one value of `kind` (station.values.Kind), named `where` in refusals
    ("cycles", "leg 1 target"). `blank`: the value a blank field stands for (omit it: a blank
    field is refused). Validated as it changes, so the invalid mark and the page's refusal line
    follow each key typed."""

    def __init__(self, value: str = "", *, kind: Kind, where: str, blank: Any = _REQUIRED, **kwargs) -> None:
        self.kind = kind
        self.where = where
        self.blank = blank
        super().__init__(value, validators=[KindValidator(self)], valid_empty=False,
                         validate_on=["changed", "submitted", "blur"], **kwargs)

    def read(self, text: str | None = None) -> Any:
        """The value of `text` (the field's own text by default): the kind's parse of it, the
        field's default when blank and it has one; InputError (the parser's message) otherwise."""
        text = self.value if text is None else text
        if not text.strip() and self.blank is not _REQUIRED:
            return self.blank
        return self.kind.parse(text, self.where)

    @property
    def refusal(self) -> str:
        """'' when the field reads; else the one-line refusal (what is wrong, what to type)."""
        try:
            self.read()
        except InputError as exc:
            return str(exc)
        return ""

    def set_kind(self, kind: Kind, where: str | None = None) -> None:
        """Narrow (or widen) the kind, e.g. to another leg's soft limits; re-checked at once."""
        if kind != self.kind or (where is not None and where != self.where):
            self.kind = kind
            self.where = self.where if where is None else where
            self.validate(self.value)


def refusals(fields) -> list[str]:
    """The refusals of `fields` (ValueFields), in order; empty when all read."""
    return [r for r in (f.refusal for f in fields if not f.disabled) if r]
