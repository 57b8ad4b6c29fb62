//! Safe Python-pickle reader (being written).
