//! The bodies of `roomlight hw …`: listing outputs, showing an image, identifying.
