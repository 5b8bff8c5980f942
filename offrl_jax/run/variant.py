"""A variant: a labelled algorithm with its resolved config and where each value came from (`Variant`), and the one
converter of a `config.json` written before variants carried their config (`Variant.from_json`)."""
from __future__ import annotations

import dataclasses
from typing import Any

from offrl_jax.algos import Config, family_of, resolve, saved_config


def check_file_name(what: str, value: object) -> None:
    """Raise ValueError unless `value` can name a file or folder inside a run directory: a non-empty string, one
    path component (no / or \\, not . or ..), no control characters.  A study's name and a variant's label do;
    a saved config.json edited to "../elsewhere" must not write outside its run."""
    if (not isinstance(value, str) or not value.strip() or value in (".", "..") or any(c in value for c in "/\\")
            or any(ord(c) < 32 or ord(c) == 127 for c in value)):
        raise ValueError(f"{what} = {value!r} must be a non-empty name without /, \\ or control characters, not . "
                         "or .. (it names files in the run directory)")


GIVEN = ("study", "flag", "variant")  # the sources of the values a study or the command line gave a variant


@dataclasses.dataclass(frozen=True)
class Variant:
    """A labelled algorithm with its resolved config: the values it trains with and where each came from."""
    label: str  # unique, used in files: "pretrained", "scratch", "lambda=0.1", ...
    algo: str
    config: Config  # the resolved, checked config (`offrl_jax.algos.resolve`): what the algorithm reads
    sources: dict[str, str] = dataclasses.field(default_factory=dict, hash=False)  # field: `SOURCES` entry
    preset: str | None = None  # the preset (`offrl_jax.algos.PRESETS`) its "preset" values came from, a record
    env: str = ""  # the env its per-env values are for ("": none, the dataclass defaults), and the dataset
    dataset: str = ""

    def __post_init__(self):
        check_file_name("Variant.label", self.label)
        if not isinstance(self.config, family_of(self.algo).config):
            raise ValueError(f"Variant.config = {self.config!r:.80} must be a {family_of(self.algo).config.__name__}")
        if self.preset is not None and not isinstance(self.preset, str):
            raise ValueError(f"Variant.preset = {self.preset!r} must be a preset's name or None")
        if not isinstance(self.env, str) or not isinstance(self.dataset, str):
            raise ValueError(f"Variant.env = {self.env!r}, dataset = {self.dataset!r} must be strings")
        fields = [f.name for f in dataclasses.fields(self.config)]
        object.__setattr__(self, "sources", {name: dict(self.sources).get(name, "default") for name in fields})

    @staticmethod
    def make(label: str, algo: str, env: str = "", dataset: str = "", preset: str | None = None,
             values: dict[str, Any] | None = None, flags: Any = ()) -> Variant:
        """`algo` resolved on `env` (and `dataset`) under `preset` and `values`, of which those named in `flags` came
        from the command line (`offrl_jax.algos.resolve`: the one place a run's values are decided)."""
        resolved = resolve(algo, env, dataset, preset, values or {}, flags)
        return Variant(label, algo, resolved.config, resolved.sources, preset, env, dataset)

    @staticmethod
    def of(label: str, algo: str, env: str = "", dataset: str = "", **values: Any) -> Variant:
        """`algo` with `values`, on `env` (and `dataset`): its per-env values there; with no env, its dataclass
        defaults and algorithm values."""
        return Variant.make(label, algo, env, dataset, values=values)

    def given(self) -> dict[str, Any]:
        """{field: value} of the values the study or the command line set (the rest: defaults, tables, presets)."""
        return {name: getattr(self.config, name) for name, source in self.sources.items() if source in GIVEN}

    def with_values(self, values: dict[str, Any], source: str = "flag") -> Variant:
        """This variant with `values` set (one line naming a field its algorithm does not have)."""
        fields = [f.name for f in dataclasses.fields(self.config)]
        if unknown := sorted(set(values) - set(fields)):
            raise ValueError(f"'{unknown[0]}' is not a hyper-parameter of {self.algo}; valid: "
                             f"{', '.join(sorted(fields))}")
        return dataclasses.replace(self, config=dataclasses.replace(self.config, **values),
                                   sources=self.sources | dict.fromkeys(values, source))

    @staticmethod
    def from_json(entry: dict, raw: dict, env: str, dataset: str) -> Variant:
        """A variant as a config.json holds it: its label and algorithm, its config in `resolved` and the sources in
        `sources`; one written before variants carried their config (`overrides`, `preset`, `flags`) is resolved as it
        was then: the one converter of old runs."""
        label, algo = entry["label"], entry["algo"]
        if "overrides" in entry:
            value = lambda x: tuple(x) if isinstance(x, list) else x  # noqa: E731  JSON has lists; configs use tuples
            try:
                pairs = {k: value(x) for k, x in entry["overrides"]}
                if not all(isinstance(k, str) for k in pairs):
                    raise TypeError
            except (TypeError, ValueError):
                raise ValueError(f"variant {label!r}: overrides = {entry['overrides']!r:.80} must be (name, value) "
                                 "pairs") from None
            flags = entry.get("flags")
            if flags is not None and (isinstance(flags, str) or not all(isinstance(f, str) for f in flags)):
                raise ValueError(f"variant {label!r}: flags = {flags!r} must be names of its overrides")
            return Variant.make(label, algo, env, dataset, entry.get("preset"), pairs,
                                None if flags is None else tuple(flags))
        config = saved_config(algo, (raw.get("resolved") or {})[label])
        return Variant(label, algo, config, (raw.get("sources") or {}).get(label, {}), entry.get("preset"),
                       entry.get("env", env), entry.get("dataset", dataset))

    def to_json(self) -> dict:
        return {"label": self.label, "algo": self.algo, "preset": self.preset, "env": self.env,
                "dataset": self.dataset}

    def again(self) -> Variant:
        """This variant resolved again from the values given it, its preset and the tables as they are now."""
        flags = None if "variant" in self.sources.values() else [k for k, s in self.sources.items() if s == "flag"]
        return Variant.make(self.label, self.algo, self.env, self.dataset, self.preset, self.given(), flags)
