"""What the EyeQ sees, in Foxglove's own schemas (the ``[foxglove]`` extra): the topics
(:mod:`.topics`), the scene (:mod:`.scene`), the one translation of decoded messages
(:mod:`.feed`), its sinks (:mod:`.mcap_sink`, :mod:`.server`), live runs (:mod:`.live`) and the
layout (:mod:`.layout`)."""
