"""The robot agent: receives its Launch Request over MQTT and supervises the brain service."""
