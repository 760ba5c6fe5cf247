"""Self-documenting config: ``ddmr run --help`` (every group's options and every key of the composed config with
its value, unit and meaning) and ``ddmr explain KEY`` (one key's meaning, unit, value, valid range and
docs/model.md section)."""

from __future__ import annotations

from ddmr_cli.cli.usage import EXIT_USAGE, UsageError, fail, one_line


def _fmt_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_fmt_value(v)}" for k, v in value.items()) + "}"
    return str(value)


def _compose_for_help(overrides: list[str], config_name: str):
    """The config ``overrides`` compose (sweeps: their first values), with the hydra node."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config import compose_config

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        return compose_config(fixed, config_name, return_hydra_config=True)
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        raise UsageError(one_line(exc, overrides)) from None


def _choices(cfg) -> dict[str, str]:
    return {k: v for k, v in cfg.hydra.runtime.choices.items() if not k.startswith("hydra/") and v is not None}


def key_table(docs, indent: str = "  ", value_width: int = 22) -> list[str]:
    """``key  value  [unit]  meaning`` lines, aligned."""
    key_w = max((len(d.key) for d in docs), default=0)
    unit_w = max((len(d.unit) for d in docs), default=0) + 2
    lines = []
    for d in docs:
        value = _fmt_value(d.value)
        unit = f"[{d.unit}]" if d.unit else ""
        lines.append(f"{indent}{d.key:<{key_w}}  {value:<{value_width}}  {unit:<{unit_w}}  {d.help}".rstrip())
    return lines


def run_help(overrides: list[str], config_name: str = "config") -> int:
    """``ddmr run --help``: the config groups and every key of the composed config with value, unit, meaning."""
    from ddmr_cli.config import ADDED_GROUPS, config_groups, group_options, key_docs

    try:
        cfg = _compose_for_help(overrides, config_name)
    except UsageError as exc:
        return fail(str(exc))
    choices = _choices(cfg)
    print(str(cfg.hydra.help.header).rstrip())
    print("\n== Config groups (group=option; * = composed) ==")
    for group in config_groups():
        options = [f"{o}*" if choices.get(group) == o else o for o in group_options(group)]
        prefix = "+" if group in ADDED_GROUPS else ""
        print(f"  {prefix}{group}: {', '.join(options)}")
    docs = key_docs(cfg)
    print(f"\n== Keys of the composed config ({len(docs)}): key  value  [unit]  meaning ==")
    print("   (ddmr explain KEY: valid range and docs/model.md section; [1] = dimensionless)")
    print("\n".join(key_table(docs)))
    print()
    print(str(cfg.hydra.help.footer).rstrip())
    return 0


def explain_topics(prefix: str) -> list[str]:
    """What ``ddmr explain`` can explain that starts with ``prefix`` (tab completion): the config groups and every
    key of the default config; for ``<group>.``, the keys of every option of that group (``controller.kp``)."""
    from ddmr_cli.config import compose_config, config_groups, group_options, iter_keys

    groups = config_groups()
    topics = [*groups, *iter_keys(compose_config([]))]
    group = prefix.split(".", 1)[0]
    if "." in prefix and group in groups:
        for option in group_options(group):
            try:
                topics += iter_keys(compose_config([f"{group}={option}"]))
            except Exception:  # noqa: BLE001 - an option that does not compose alone offers no keys
                continue
    return sorted({t for t in topics if t.startswith(prefix)})


def cmd_explain(argv: list[str]) -> int:
    """``ddmr explain KEY [OVERRIDES...]``: one key's meaning, unit, value, valid range and model reference."""
    import difflib

    from ddmr_cli.config import compose_config, config_groups, group_options, iter_keys, key_doc

    if not argv or argv[0] in ("-h", "--help"):
        print("usage: ddmr explain KEY [OVERRIDES...]\n\nThe meaning, unit, value (composed default, or with the "
              "overrides), valid range and docs/model.md\nsection of a config key. Examples:\n"
              "  ddmr explain controller.switching_gain\n  ddmr explain controller.kp controller=pid\n"
              "  ddmr explain terrain.zones.very_rough.roughness\n  ddmr explain controller")
        return 0 if argv else EXIT_USAGE
    key, overrides = argv[0], argv[1:]
    try:
        cfg = _compose_for_help(overrides, "config")
    except UsageError as exc:
        return fail(str(exc))
    composed_from = None
    default_choice = _choices(cfg).get(key.split(".", 1)[0], "?")
    try:
        doc = key_doc(cfg, key)
    except KeyError:
        doc = None
        group = key.split(".", 1)[0]
        if group in config_groups() and "." in key and not any(o.partition("=")[0] == group for o in overrides):
            for option in group_options(group):  # a key of another option of the group (controller.kp: pid)
                other = compose_config([*overrides, f"{group}={option}"], return_hydra_config=True)
                try:
                    doc, cfg, composed_from = key_doc(other, key), other, f"{group}={option}"
                    break
                except KeyError:
                    continue
        if doc is None:
            known = [k for k in iter_keys(cfg)] + [k for k in cfg if k != "hydra"]
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            return fail(f"key={key}: not a key of the composed config{hint} (ddmr run --help lists every key)")
    choices = _choices(cfg)
    print(f"{doc.key} = {_fmt_value(doc.value)}" if doc.is_leaf else doc.key)
    print(f"  meaning: {doc.help or '-'}")
    print(f"  unit:    {doc.unit or '-'}{'  (dimensionless)' if doc.unit == '1' else ''}")
    if doc.is_leaf:
        where = ", ".join(f"{g}={choices[g]}" for g in choices if g == key.split('.')[0])
        label = "value:  " if overrides else "default:"
        note = f"composed from {composed_from or where or 'config.yaml'}" + (" and the overrides" if overrides else "")
        print(f"  {label} {_fmt_value(doc.value)}  ({note})")
    print(f"  range:   {doc.range or '-'}")
    print(f"  see:     {doc.reference}")
    if doc.model:
        from importlib.resources import as_file

        from ddmr_cli.config import model_doc

        with as_file(model_doc()) as path:  # a file of the installed package (a wheel install too)
            print(f"  read:    {path}")
    if composed_from:
        print(f"  note:    not a key of the composed {key.split('.')[0]}={default_choice}; "
              f"set it with {composed_from} (e.g. ddmr run {composed_from} {key}=...)")
    if not doc.is_leaf:
        if key in config_groups():
            options = [f"{o}*" if choices.get(key) == o else o for o in group_options(key)]
            print(f"  options: {', '.join(options)}   (* = composed; choose with {key}=OPTION)")
        node = cfg
        for part in key.split("."):
            node = node[part]
        print("  keys:")
        print("\n".join(key_table([key_doc(cfg, f"{key}.{k}") for k in iter_keys(node)], indent="    ")))
    return 0


__all__ = ["explain_topics", "run_help", "cmd_explain", "key_table"]
