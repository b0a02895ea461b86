"""Files the programs read and write: YAML read the way YAML 1.2 and JSON read numbers, the
check that an output can be written before a run starts, and whether a source is a bag."""

import os


def output_problem(path):
    """Why an output file cannot be written at `path`, checked before a run starts, or None:
    "folder '...' does not exist" or "folder '...' is not writable"."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        return f"folder '{folder}' does not exist"
    if not os.access(folder, os.W_OK):
        return f"folder '{folder}' is not writable"
    return None


def is_bag(spec):
    """Whether --source names a ROS 1 bag (a file ending in .bag)."""
    spec = str(spec)
    return spec.lower().endswith('.bag') and os.path.isfile(spec)


def yaml_loader():
    """PyYAML's SafeLoader, also reading 1e3 and 1e-05 as numbers (YAML 1.2 and JSON do; PyYAML
    follows YAML 1.1, which wants a dot, and makes them strings)."""
    import re

    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_implicit_resolver(
        'tag:yaml.org,2002:float', re.compile(r'^[-+]?[0-9][0-9_]*(\.[0-9_]*)?[eE][-+]?[0-9]+$'),
        list('-+0123456789'))
    return Loader


def load_yaml(text):
    """One YAML document from text, read as yaml_loader() does."""
    import yaml

    return yaml.load(text, Loader=yaml_loader())  # noqa: S506 (a SafeLoader)


def read_yaml(path, error, what='YAML'):
    """The document in a YAML file (which also reads JSON); when it cannot be read, `error`
    (an exception type) is raised with the file and the reason, never a traceback."""
    import yaml  # Debian's python3-yaml, which rospy itself needs

    try:
        with open(path, encoding='utf-8') as f:
            return load_yaml(f)
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:  # on one line: YAML's own
        raise error(f"{path}: cannot read as {what}: {' '.join(str(e).split())}") from None
