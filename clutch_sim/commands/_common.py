"""Options and helpers shared by several subcommands."""
from __future__ import annotations


def add_topic_options(parser) -> None:
    from clutch_model.formats.topics import TopicNames

    d = TopicNames()
    g = parser.add_argument_group("bag topics")
    g.add_argument("--topic-force", default=d.applied_force, help="applied force topic (%(default)s)")
    g.add_argument("--topic-slip", default=d.slip_speed, help="slip speed topic (%(default)s)")
    g.add_argument("--topic-sump", default=d.sump_temperature, help="sump temperature topic (%(default)s)")
    g.add_argument("--topic-torque", default=d.measured_torque, help="measured torque topic (%(default)s)")
    g.add_argument("--topic-pack", default=d.pack_temperature, help="pack temperature topic (%(default)s)")


def topics_from_args(args):
    from clutch_model.formats.topics import TopicNames

    return TopicNames(args.topic_force, args.topic_slip, args.topic_sump, args.topic_torque, args.topic_pack)


def load_runs(args, bags):
    from clutch_model.formats.bag_reader import read_bags

    return read_bags(bags, topics_from_args(args), progress=True)
