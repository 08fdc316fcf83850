"""What the recorder counts as lost (sit2stand.io.losses): gaps in one writer's publication sequence numbers, never
a second writer's numbers, and the larger of that and DDS's own count."""

from __future__ import annotations

from sit2stand.io.losses import SEQUENCE_UNKNOWN, SequenceGaps, TopicLosses, WithMessageInfo


def one_writer() -> int:
    return 1


def seen(numbers, publishers=one_writer) -> SequenceGaps:
    gaps = SequenceGaps()
    for n in numbers:
        gaps.see(n, publishers)
    return gaps


def test_the_samples_between_two_received_ones_of_one_writer_are_missed():
    assert seen([1, 2, 3]).missed == 0
    assert seen([1, 2, 19, 20, 1951, 2000]).missed == 16 + 1930 + 48


def test_a_reader_matched_late_has_not_missed_what_came_before_its_first_sample():
    assert seen([101, 102, 103]).missed == 0


def test_gaps_are_not_counted_while_a_second_writer_is_matched():
    assert seen([1, 2, 50, 51], publishers=lambda: 2).missed == 0


def test_numbers_that_go_back_are_not_one_writers_and_stop_the_count():
    gaps = seen([1000, 1001, 1, 2, 1002, 1500])     # a second writer came and went while the recorder was behind
    assert (gaps.missed, gaps.counting) == (0, False)
    restarted = seen([1, 2, 5, 1, 2, 9])            # the gap before the restart stays counted
    assert (restarted.missed, restarted.counting) == (2, False)


def test_an_rmw_without_sequence_numbers_leaves_the_topic_to_dds():
    assert not seen([None]).counting
    assert not seen([1, SEQUENCE_UNKNOWN + 5, 9]).counting
    assert seen([1, SEQUENCE_UNKNOWN + 5, 9]).missed == 0


def test_a_topics_loss_is_the_larger_of_dds_count_and_the_gaps():
    losses = TopicLosses()
    for n in (1, 2, 3, 40):                      # 36 missed between 3 and 40
        losses.see("/robot/cop", n, one_writer)
    for n in (1, 2):
        losses.see("/robot/joint_states", n, one_writer)
    losses.dds_lost("/robot/cop", 10)             # a GAP-answered loss is not in DDS's count
    losses.dds_lost("/human/com", 7)              # a loss after the last sample is only in DDS's count
    assert losses.lost() == {"/human/com": 7, "/robot/cop": 36}
    losses.forget("/human/com")
    assert losses.lost() == {"/robot/cop": 36}


def test_the_callback_gets_message_and_info_however_the_executor_passes_them():
    got = []
    callback = WithMessageInfo(lambda message, info: got.append((message, info["publication_sequence_number"])))
    callback(b"a", {"publication_sequence_number": 1})             # SingleThreadedExecutor
    callback((b"b", {"publication_sequence_number": 2}))           # rclpy 7.1.6's EventsExecutor
    assert got == [(b"a", 1), (b"b", 2)]
