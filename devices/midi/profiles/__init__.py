"""The shipped MIDI controller profiles (data files; see devices.midi.profile)."""
