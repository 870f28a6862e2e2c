"""Hostile configs and options (issue 22): the families `yaml`, `options` and `values`.

- `yaml`: damaged and hostile YAML configs: circular aliases, alias bombs, deep nesting, huge integers, huge
  files, tags, binary and invalid UTF-8, duplicate keys, long keys and values, and random byte mutations of the
  shipped configs, read by `vehid simulate`.
- `options`: hostile command-line options for every command: output names over the file system's limits, outputs
  that are directories or files where a directory is expected, seeds, runs and jobs out of range, malformed
  `--set`, `--vary` and `--shard`, out-of-range `--verify`, `--format`, `--published`.
- `values`: every numeric config key of the car and the damper set to a hostile number (0, negative, tiny, huge,
  NaN, infinite, a 400-digit integer, a string, a list, or a value just inside or outside its range), then
  simulated (and, for some, identified with a one-run campaign).

Every case is cheap (a short simulation, a one-run campaign of one iteration) so that the suite runs hundreds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from . import ROOT, Case, family

CAR = ROOT / "configs" / "gokdag2015" / "base.yaml"
RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"
DAMPER = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
SHIPPED = sorted((ROOT / "configs").glob("**/*.yaml"))

# a car campaign that costs a fraction of a second: 0.5 s of the bump, one run of one DE iteration
TINY_CAR = (
    "simulation.duration=0.5", "identify.algorithm.name=de", "identify.algorithm.population=4",
    "identify.algorithm.iterations=1", "identify.runs=1",
)  # fmt: skip
TINY_DAMPER = ("identify.algorithm.population=4", "identify.algorithm.iterations=1", "identify.runs=1")


def _sets(items) -> list[str]:
    out: list[str] = []
    for item in items:
        out += ["--set", item]
    return out


def _pick(rng: np.random.Generator, seq):
    return seq[int(rng.integers(len(seq)))]


def _simulate(folder: Path, config: Path, what: str, family_name: str = "yaml", extra=()) -> Case:
    out = "out.csv"
    return Case(family_name, what, ("simulate", str(config), "-o", out, *extra))


# ------------------------------------------------------------------------------------------ yaml


def _alias_bomb(rng) -> tuple[str, str]:
    width, depth = int(rng.integers(3, 12)), int(rng.integers(4, 14))
    lines = [f"l0: &l0 [{', '.join(['lol'] * width)}]"]
    for i in range(1, depth):
        lines.append(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * width)}]")
    return "\n".join(lines) + "\n", f"an alias bomb of {width}^{depth} values ({sum(map(len, lines))} bytes)"


def _circular(rng) -> tuple[str, str]:
    base = CAR.read_text()
    kind = int(rng.integers(4))
    if kind == 0:
        text = "a: &a [*a]\n"
    elif kind == 1:
        text = "a: &a\n  b: *a\n"
    elif kind == 2:
        text = base.replace("vehicle:\n", "vehicle: &car\n", 1) + "\nextra: {back: *car}\n"
        text = text.replace("  cr: 3500", "  cr: 3500\n  self: *car")
    else:
        text = "x: &x\n  - &y [*x, *y]\n"
    return text, f"a circular alias (form {kind})"


def _deep(rng) -> tuple[str, str]:
    depth = int(_pick(rng, [60, 65, 100, 1000, 5000, 20000]))
    kind = int(rng.integers(3))
    if kind == 0:
        text = "vehicle: " + "[" * depth + "]" * depth + "\n"
    elif kind == 1:
        text = "road: " + "{a: " * depth + "1" + "}" * depth + "\n"
    else:  # block style: indentation
        depth = min(depth, 300)
        text = "".join(f"{' ' * i}k{i}:\n" for i in range(depth)) + " " * depth + "v: 1\n"
    return text, f"nesting {depth} deep (form {kind})"


def _big_number(rng) -> tuple[str, str]:
    digits = int(_pick(rng, [40, 309, 400, 401, 4300, 5000, 20000]))
    key = _pick(rng, ["  m: 1300", "  kf: 45000", "  runs: 30", "  seed: 2015", "  duration: 3.0", "  level: 0.10"])
    sign = _pick(rng, ["", "-", "+"])
    number = _pick(rng, [sign + "9" * digits, f"1e{'9' * min(digits, 50)}", f"0x{'f' * digits}", f"0.{'1' * digits}"])
    name = key.split(":")[0]
    what = f"{name.strip()} = a number of {len(number)} characters"
    return CAR.read_text().replace(key, f"{name}: {number}", 1), what


def _huge(rng) -> tuple[str, str]:
    size = int(_pick(rng, [200_000, 262_000, 262_145, 300_000, 2_000_000]))
    base = CAR.read_text()
    kind = int(rng.integers(3))
    if kind == 0:
        text = base + "#" + "x" * size + "\n"
    elif kind == 1:
        text = base.replace("system: vehicle", f"system: vehicle\nnote: {'y' * size}", 1)
    else:
        text = base + "extra: [" + ", ".join(["1"] * (size // 3)) + "]\n"
    return text, f"a config of about {len(text)} bytes (form {kind})"


TAGS = [
    "!!python/object/apply:os.system ['echo pwned']", "!!python/name:os.system", "!!python/object:__main__.X {}",
    "!!binary aGVsbG8=", "!!set {a, b}", "!!omap [a: 1]", "!!timestamp 2001-12-14", "!custom 3", "!!float 1e999",
    "!!int 0b101", "!!str 1300", "!!null ''", "!!map {a: 1}", "!!seq [1]", "&anchor 1300", "*undefined",
]  # fmt: skip


def _tagged(rng) -> tuple[str, str]:
    tag = _pick(rng, TAGS)
    key = _pick(rng, ["  m: 1300", "  speed_kmh: 20", "  name: abc", "  runs: 30", "sensors: both", "  level: 0.10"])
    return CAR.read_text().replace(key, f"{key.split(':')[0]}: {tag}", 1), f"{key.strip()} tagged {tag!r}"


def _encoding(rng) -> tuple[bytes, str]:
    base = CAR.read_bytes()
    kind = int(rng.integers(6))
    if kind == 0:
        return base.decode().encode("utf-16"), "the config in UTF-16"
    if kind == 1:
        return b"\xef\xbb\xbf" + base, "a UTF-8 byte-order mark"
    if kind == 2:
        at = int(rng.integers(len(base)))
        return base[:at] + b"\x00" + base[at:], f"a NUL byte at {at}"
    if kind == 3:
        at = int(rng.integers(len(base)))
        return base[:at] + bytes(rng.integers(128, 256, 4, dtype=np.uint8)) + base[at:], f"invalid UTF-8 at {at}"
    if kind == 4:
        return bytes(rng.integers(0, 256, int(rng.integers(1, 4000)), dtype=np.uint8)), "random binary bytes"
    return base.replace(b"\n", b"\r"), "old Mac line ends (CR only)"


def _duplicate(rng) -> tuple[str, str]:
    base = CAR.read_text()
    line = _pick(rng, ["  m: 1300", "  speed_kmh: 20", "  runs: 30", "noise:", "  level: 0.10", "  dt: 0.001"])
    indent = line[: len(line) - len(line.lstrip())]
    extra = f"{line}\n" if line.endswith(":") is False else f"{line}\n{indent}  level: 0.2\n"
    return base.replace(line + "\n", line + "\n" + extra, 1), f"{line.strip()} given twice"


def _long_text(rng) -> tuple[str, str]:
    n = int(_pick(rng, [300, 5_000, 100_000]))
    base = CAR.read_text()
    kind = int(rng.integers(4))
    if kind == 0:
        return base.replace("  m: 1300", f"  m: {'x' * n}", 1), f"vehicle.m = a string of {n} characters"
    if kind == 1:
        return base.replace("  m: 1300", f"  {'k' * n}: 1300", 1), f"a key of {n} characters"
    if kind == 2:
        return base.replace("  name: abc", f"  name: {'a' * n}", 1), f"an algorithm name of {n} characters"
    return base.replace("sensors: both", f"sensors: [{', '.join(['both'] * (n // 6))}]", 1), "a long list as sensors"


def _structure(rng) -> tuple[str, str]:
    raw = yaml.safe_load(_pick(rng, [CAR, RIG, DAMPER]).read_text())
    section = _pick(rng, sorted(raw))
    value = _pick(rng, [None, [], {}, 0, "", [1, 2], {"a": {"b": None}}, True, "~", 1e308, -1])
    raw[section] = value
    return yaml.safe_dump(raw), f"section {section!r} replaced by {value!r}"


def _mutated(rng) -> tuple[bytes, str]:
    source = _pick(rng, SHIPPED)
    data = bytearray(source.read_bytes())
    n = int(_pick(rng, [1, 1, 2, 3, 5, 10, 30]))
    for _ in range(n):
        at = int(rng.integers(len(data)))
        op = int(rng.integers(4))
        if op == 0:
            data[at] ^= 1 << int(rng.integers(8))
        elif op == 1:
            data.insert(at, int(_pick(rng, list(b":-[]{}&*!|>'\"#%@`,?\t\n 0123456789e.") + [int(rng.integers(256))])))
        elif op == 2 and len(data) > 1:
            del data[at]
        else:
            data[at:at] = data[int(rng.integers(len(data))) :][: int(rng.integers(1, 40))]
    return bytes(data), f"{n} byte mutations of {source.relative_to(ROOT)}"


YAML_KINDS = (
    _alias_bomb, _circular, _deep, _big_number, _huge, _tagged, _encoding, _duplicate, _long_text, _structure,
    _mutated, _mutated, _mutated, _mutated,
)  # fmt: skip


@family("yaml")
def hostile_yaml(rng: np.random.Generator, folder: Path) -> Case:
    text, what = _pick(rng, YAML_KINDS)(rng)
    config = folder / "config.yaml"
    config.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogateescape"))
    return _simulate(folder, config, what)


# ------------------------------------------------------------------------------------------ options

BIG_INTS = ["-1", "0", str(2**31), str(2**63 - 1), str(2**63), str(2**64), "-" + str(2**63), "10" + "0" * 40,
            "9" * 5000, "1e3", "abc", "", " 3", "0x10", "1.5", "٣"]  # fmt: skip


def _long_name(rng, suffix: str, folder: Path | None = None) -> tuple[str, str]:
    """An output name the file system cannot take, or just can (`folder`: where a directory named as the output
    is made)."""
    if folder is not None:
        (folder / f"sub{suffix}").mkdir(parents=True, exist_ok=True)
    kind = int(rng.integers(6))
    if kind == 0:
        n = int(_pick(rng, [250, 251, 255, 256, 300, 1000]))
        return "o" * (n - len(suffix)) + suffix, f"a name of {n} bytes"
    if kind == 1:
        n = int(_pick(rng, [84, 85, 86, 120]))  # three bytes a character: 255 bytes near 85 characters
        return "€" * n + suffix, f"a name of {n} three-byte characters ({3 * n + len(suffix)} bytes)"
    if kind == 2:
        depth = int(_pick(rng, [10, 17, 20, 40]))
        return "/".join(["d" * 250] * depth) + "/x" + suffix, f"a path of {251 * depth} bytes"
    if kind == 3:
        return _pick(rng, [".", "..", "/", "./", "sub/", "missing/dir/x" + suffix, "x" + suffix + "/"]), "an odd name"
    if kind == 4:
        return _pick(rng, ["x.CSV", "x", "x.", ".csv", "x.exe", "-x" + suffix]), "an odd suffix"
    return "sub" + suffix, "a directory where a file is expected"


def _set_items(rng) -> tuple[list[str], str]:
    kind = int(rng.integers(12))
    items = [
        ["", "=", "a", "=1", ".a=1", "a..b=1", "a.=1", " . =1"][int(rng.integers(8))],
        _pick(rng, ["vehicle.m.x=1", "vehicle=", "vehicle=[1,2]", "road=3", "identify.unknowns=[]", "identify={}"]),
        "identify.seed=!!python/object/apply:os.system ['true']",
        "vehicle.m=" + "[" * int(_pick(rng, [70, 5000])),
        "noise.level=&a [*a]",
        "vehicle.m=1e30" if rng.random() < 0.5 else "vehicle.cr=1e30",
        "k" * int(_pick(rng, [300, 100_000])) + "=1",
        "vehicle.m=" + "x" * int(_pick(rng, [300, 100_000])),
        ".".join(["a"] * int(_pick(rng, [60, 65, 1000]))) + "=1",
        "identify.algorithm.name=" + _pick(rng, ["", "abc " * 100, "\t", "ga\n"]),
        "vehicle.m=" + _pick(rng, [".nan", ".inf", "-.inf", "1e999", "9" * 5000, "0x" + "f" * 300, "~", "null"]),
        "a: &a [l, l, l, l, l, l, l, l]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a]\nc: [*b, *b, *b, *b, *b, *b, *b, *b]",
    ][kind]
    items = items if isinstance(items, list) else [items]
    return items, f"--set {items[0][:60]!r}"


def _campaign_options(rng, command: str, folder: Path) -> tuple[list[str], str]:
    kind = int(rng.integers(6))
    if kind == 0:
        option = _pick(rng, ["--seed", "--runs", "--jobs"])
        value = _pick(rng, BIG_INTS)
        return [option, value], f"{option} {value[:30]}"
    if kind == 1:
        if command == "sweep":
            (folder / "sub").write_text("a file where the sweep's directory should be")
            name, what = _long_name(rng, "")
        else:
            name, what = _long_name(rng, ".h5", folder)
        return ["-o", name], f"-o {what}"
    if kind == 2:
        items, what = _set_items(rng)
        return _sets(items), what
    if kind == 3 and command == "sweep":
        shard = _pick(rng, ["0/1", "2/1", "1/0", "a/b", "1/2/3", "-1/2", "1/", "/", "1/" + "9" * 5000, " 1 / 2 ",
                            "1.5/2", "1/99999999999999999999", "١/٢", ""])  # fmt: skip
        return ["--shard", shard], f"--shard {shard[:30]!r}"
    if kind == 4:
        name, what = _long_name(rng, ".json", folder)
        return ["--json", name] if command == "identify" else ["--executor", _pick(rng, ["dask", "", "x" * 300])], what
    return ["--seed", _pick(rng, BIG_INTS), "--runs", _pick(rng, ["1", "0", str(2**63)])], "--seed and --runs"


def _vary(rng) -> list[str]:
    if rng.random() < 0.7:
        return ["--vary", "noise.level=0.1"]
    value = _pick(rng, ["0.1", "0.1,0.2", "", ",", "0.1,,0.2", "[", "0." + "1" * 300, "x" * 300, "a/b", "../up",
                        "1,1", "0.1]", "&a [*a]"])  # fmt: skip
    key = _pick(rng, ["noise.level", "noise.level", "", "vehicle", "x" * 300, "identify.seed"])
    return ["--vary", f"{key}={value}" if rng.random() < 0.9 else key]


@family("options")
def hostile_options(rng: np.random.Generator, folder: Path) -> Case:
    command = _pick(rng, ["simulate", "identify", "identify", "sweep", "sweep", "design", "report", "diagnose",
                          "check"])  # fmt: skip
    car = str(CAR)
    if command in ("identify", "sweep"):
        opts, what = _campaign_options(rng, command, folder)
        base = ["identify", car, "-o", "c.h5"] if command == "identify" else ["sweep", car, "-o", "s", *_vary(rng)]
        args = [*base, "--jobs", "1", *_sets(TINY_CAR), *opts]
        return Case("options", f"{command} {what}", tuple(args))
    if command == "simulate":
        kind = int(rng.integers(3))
        if kind == 0:
            name, what = _long_name(rng, ".csv", folder)
            return Case("options", f"simulate -o {what}", ("simulate", car, "-o", name, *_sets(TINY_CAR)))
        if kind == 1:
            seed = _pick(rng, BIG_INTS)
            return Case("options", f"simulate --seed {seed[:30]}", ("simulate", car, "-o", "o.csv", "--seed", seed))
        items, what = _set_items(rng)
        return Case("options", f"simulate {what}", ("simulate", car, "-o", "o.csv", *_sets(TINY_CAR), *_sets(items)))
    if command == "design":
        opt = _pick(rng, [["--verify", _pick(rng, BIG_INTS)], ["--jobs", _pick(rng, BIG_INTS[:9])],
                          ["-o", _long_name(rng, ".yaml")[0]], ["--plots", _long_name(rng, "")[0]],
                          _sets(_set_items(rng)[0])])  # fmt: skip
        if opt[0] in ("--verify", "--jobs") and opt[1] in ("1", "0", str(2**31), str(2**63 - 1)):
            opt = [opt[0], "-1"]  # a valid design runs for seconds: the case is the refusal
        config = ROOT / "configs" / "gokdag2015" / "design.yaml"
        return Case("options", f"design {' '.join(opt)[:60]}", ("design", str(config), *opt, "--set", "x=1"))
    if command == "report":
        opt = _pick(rng, [["--format", _pick(rng, ["", "xml", "x" * 300, "md"])],
                          ["-o", _long_name(rng, ".md", folder)[0]], ["--plots", _long_name(rng, "")[0]],
                          ["--published", "pub.yaml"]])  # fmt: skip
        (folder / "pub.yaml").write_text(_alias_bomb(rng)[0] if rng.random() < 0.5 else _deep(rng)[0])
        return Case("options", f"report {' '.join(opt)[:60]}", ("report", "nothing.h5", *opt))
    data = _pick(rng, ["missing.csv", "o" * 300 + ".csv", "/".join(["d" * 250] * 20), ".", "x.mf4"])
    opt = _pick(rng, [["--data", data], ["--json", _long_name(rng, ".json", folder)[0]], _sets(_set_items(rng)[0])])
    config = str(CAR)
    if command == "diagnose":
        opt += ["--validate", data]
    return Case("options", f"{command} {' '.join(opt)[:60]}", (command, config, *opt))


# ------------------------------------------------------------------------------------------ values

CAR_KEYS = [
    f"vehicle.{k}" for k in ("m", "mf", "mr", "Ix", "Iy", "a1", "b1", "kf", "kr", "ktf", "ktr", "kR", "cf", "cr")
]
CAR_KEYS += [
    "road.speed_kmh", "road.bump.length", "road.bump.plateau", "road.bump.start_time", "road.bump.heights",
    "simulation.duration", "simulation.dt", "noise.level", "noise.sigma.acc", "noise.sigma.disp",
    "identify.bounds", "identify.runs", "identify.seed", "identify.budget", "identify.algorithm.population",
    "identify.algorithm.iterations", "identify.limits.m", "vehicle.wheelbase", "vehicle.track",
]  # fmt: skip
RIG_KEYS = ["road.random.n_min", "road.random.n_max", "road.random.fade_in", "road.speed_kmh", "layout.0.x",
            "noise.sigma.acc", "vehicle.m", "vehicle.cr"]  # fmt: skip
DAMPER_KEYS = [
    "bench.amplitude", "bench.frequency", "bench.velocity", "bench.cycles", "bench.dt", "bench.control",
    "bench.substeps", "noise.level", "damper.parameters.c0", "damper.parameters.fc", "damper.parameters.v_eps",
    "damper.parameters.k1", "damper.parameters.x0", "identify.realtime_dt", "identify.bounds", "identify.seed",
    "identify.runs",
]  # fmt: skip


SIZE_KEYS = {"identify.runs", "identify.budget", "identify.algorithm.population", "identify.algorithm.iterations",
             "simulation.duration", "simulation.dt", "bench.cycles", "bench.dt", "bench.frequency", "bench.velocity",
             "bench.substeps", "identify.realtime_dt"}  # fmt: skip
COUNTS = ["0", "-1", "1.5", "2", "3", "4", str(2**63), "1e30", "100001", "10001", "1000001", "1e999", "abc", "[]"]


def _number(rng) -> str:
    """A hostile number (or not a number), as YAML text."""
    kind = int(rng.integers(8))
    if kind == 0:
        return _pick(rng, ["0", "-0", "-1", ".nan", ".inf", "-.inf", "1e999", "-1e999", "~", "true", "''", "[]", "{}"])
    if kind == 1:
        return f"{_pick(rng, ['', '-'])}1.0e{int(rng.integers(-320, 320))}"
    if kind == 2:
        return _pick(rng, ["9" * 400, "-" + "9" * 300, str(2**63), str(2**64), str(-(2**63) - 1), str(2**31)])
    if kind == 3:
        return _pick(rng, ["'1e30'", "'abc'", "1,5", "1_000", "0x1F", "0o17", "1:30", "[1, 2]", "[.nan, 1]", "{a: 1}"])
    if kind == 4:  # a list of two values, for pairs (bounds, limits)
        return f"[{_number_scalar(rng)}, {_number_scalar(rng)}]"
    if kind == 5:  # a list of four, for the bump heights
        return "[" + ", ".join(_number_scalar(rng) for _ in range(4)) + "]"
    return _number_scalar(rng)


def _number_scalar(rng) -> str:
    """A number near a range's edge or across magnitudes."""
    edge = float(_pick(rng, [0, 1e-7, 1e-4, 1e-3, 0.01, 0.1, 1, 10, 100, 1000, 1e4, 1e5, 1e6, 1e8, 1e10, 1e12]))
    value = edge * float(_pick(rng, [1, 1.0000001, 0.9999999, 2, 0.5, -1]))
    return repr(value) if rng.random() < 0.8 else str(int(value))


@family("values")
def hostile_values(rng: np.random.Generator, folder: Path) -> Case:
    kind = _pick(rng, ["car", "car", "car", "rig", "damper", "damper"])
    config, keys, tiny = {"car": (CAR, CAR_KEYS, TINY_CAR), "rig": (RIG, RIG_KEYS, TINY_CAR),
                          "damper": (DAMPER, DAMPER_KEYS, TINY_DAMPER)}[kind]  # fmt: skip
    chosen = [_pick(rng, keys) for _ in range(int(_pick(rng, [1, 1, 1, 2, 3])))]
    sets = [f"{key}={_number(rng)}" for key in chosen]
    what = f"{kind}: " + ", ".join(sets)[:120]
    if kind == "rig":
        tiny = ("simulation.duration=0.5", "simulation.dt=0.002")
    if rng.random() < 0.25 and kind != "rig":  # a one-run campaign of one iteration: the search box, the bound
        # a valid but large campaign or record runs as long as the user asked: such values go to `simulate`
        sets = [
            f"{k}={_pick(rng, COUNTS)}" if k in SIZE_KEYS else f"{k}={v}" for k, v in (i.split("=", 1) for i in sets)
        ]
        args = ("identify", str(config), "-o", "c.h5", "--jobs", "1", *_sets(tiny), *_sets(sets))
        return Case("values", f"identify {', '.join(sets)[:120]}", args)
    sim = [t for t in tiny if t.startswith("simulation.")]
    return Case("values", f"simulate {what}", ("simulate", str(config), "-o", "out.csv", *_sets(sim), *_sets(sets)))
